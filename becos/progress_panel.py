"""The progress panel of a workflow run in a terminal (profiles/default turns it on).

snakemake-logger-plugin-rich draws one bar per rule and a total; :func:`tune` adds what a user of a
long run wants to read from it: ``done/total`` jobs and an estimated time left, and keeps the total
right when the dataset checkpoint adds the remesh and chunk jobs (Snakemake's progress events carry
the real ``done``/``total``; the plugin alone counts only the jobs announced before the checkpoint).
Called from workflow/rules/common.smk; does nothing when the plugin is not in use (plain output).
"""

from __future__ import annotations

from datetime import timedelta

TOTAL = "Total Progress"
"""The plugin's name of its overall bar."""


def _eta_column():
    from rich.progress import ProgressColumn
    from rich.text import Text

    class EtaColumn(ProgressColumn):
        """Time left for the overall bar: elapsed time x jobs left / jobs done (jobs differ in length,
        so an estimate that settles as the run goes)."""

        def render(self, task) -> Text:
            if task.description.find(TOTAL) < 0:
                return Text("")
            if task.finished or not task.completed or not task.total or task.elapsed is None:
                return Text("ETA --:--", style="dim")
            left = task.elapsed * max(task.total - task.completed, 0) / task.completed
            return Text(f"ETA {timedelta(seconds=round(left))}", style="cyan")

    return EtaColumn()


def tune(handlers) -> bool:
    """Add ``done/total`` and ETA columns to the rich plugin's panel among Snakemake's log ``handlers``
    (``workflow.logger_manager.get_log_handlers()``) and feed its total bar from Snakemake's progress
    events. Returns whether a rich panel was found (False: plain output, nothing changed)."""
    for handler in handlers:
        events = getattr(handler, "event_handler", None)
        progress = getattr(events, "progress", None)
        if progress is None or not hasattr(progress, "columns") or not hasattr(events, "handle_progress"):
            continue
        from rich.progress import BarColumn, MofNCompleteColumn

        columns = list(progress.columns)
        at = next((i for i, c in enumerate(columns) if isinstance(c, BarColumn)), len(columns) - 1)
        columns.insert(at + 1, MofNCompleteColumn())
        columns.append(_eta_column())
        progress.columns = tuple(columns)
        plugin_handle_progress = events.handle_progress

        def handle_progress(event_data, _plugin=plugin_handle_progress, _events=events, **kwargs):
            _plugin(event_data, **kwargs)
            display = getattr(_events, "progress_display", None)
            task = getattr(display, "rule_tasks", {}).get(TOTAL)
            if task is not None and event_data.total:
                _events.total_jobs, _events.completed = event_data.total, event_data.done
                _events.progress.update(task, total=event_data.total, completed=event_data.done)

        events.handle_progress = handle_progress
        return True
    return False
