"""What a user sees (issue #17): config errors as one line each, a failed job's own error line on the
console, the progress panel in a terminal. Real Snakemake runs of the real Snakefile (with its default
workflow profile, profiles/default), in a pseudo-terminal where the terminal matters.
"""

from __future__ import annotations

import json
import os
import pty
import re
import select
import subprocess
import sys
import time
from pathlib import Path

import pytest
from snakemake_cmd import snakemake_cmd
from tiny_tosca import tosca_config, write_config_file

from becos.errors import ConfigError
from becos.joblog import error_lines, failure_report
from becos.workflow import check_config_files, resolve_config

REPO = Path(__file__).resolve().parents[1]
NOT_SEEN = ("Traceback", "ConfigError in file", "WorkflowError in file", "Failed validating", 'File "')


def run_snakemake(
    cwd: Path, *args: str, workdir: Path | None = None, env: dict | None = None
) -> subprocess.CompletedProcess:
    """Snakemake from ``cwd`` (pipes: not a terminal, so plain output); ``workdir``: ``-d`` and
    ``--configfile`` of its ``config.yaml`` (else ``args`` name what they need)."""
    return subprocess.run(
        snakemake_cmd(workdir, *args),
        cwd=cwd,
        capture_output=True,
        text=True,
        env=dict(os.environ, PYTHONUNBUFFERED="1", **(env or {})),
    )


def run_in_terminal(cwd: Path, *args: str, env: dict | None = None, timeout: float = 120) -> tuple[int, str]:
    """Snakemake with stdout and stderr on a pseudo-terminal (what a user at a terminal sees); returns
    its exit status and everything it wrote (terminal control sequences removed)."""
    master, slave = pty.openpty()
    full_env = dict(os.environ, PYTHONUNBUFFERED="1", COLUMNS="120", LINES="40", TERM="xterm-256color", **(env or {}))
    proc = subprocess.Popen(snakemake_cmd(None, *args), cwd=cwd, stdin=slave, stdout=slave, stderr=slave, env=full_env)
    os.close(slave)
    chunks, deadline = [], time.monotonic() + timeout
    while time.monotonic() < deadline:
        ready, _, _ = select.select([master], [], [], 0.2)
        if ready:
            try:
                data = os.read(master, 65536)
            except OSError:  # the terminal closed: the process ended
                break
            if not data:
                break
            chunks.append(data)
        elif proc.poll() is not None:
            break
    code = proc.wait(timeout=max(deadline - time.monotonic(), 1))
    os.close(master)
    text = b"".join(chunks).decode(errors="replace")
    return code, re.sub(r"\x1b\[[0-9;?]*[A-Za-z]", "", text)  # without colours and cursor moves


def problem_lines(text: str) -> list[str]:
    return [line for line in text.splitlines() if line.startswith("becos config: ")]


# --- config errors ---------------------------------------------------------------------------------
KEY_KINDS = {  # kind: (override, key named in the line, words of the problem)
    "unknown key": ({"min_overlapp": 0.2}, "min_overlapp", "did you mean 'min_overlap'"),
    "wrong type": ({"n_cam_pos": "ten"}, "n_cam_pos", "not an integer"),
    "enum": ({"cam_pos_regime": "hi"}, "cam_pos_regime", "one of high, medium, low"),
    "negative cap": ({"caps": {"train": -1}}, "caps.train", "below the minimum 0"),
    "n_chunks 0": ({"n_chunks": 0}, "n_chunks", "below the minimum 1"),
    "reversed overlap range": ({"min_overlap": 0.8, "max_overlap": 0.2}, "min_overlap", "reversed"),
    "unknown dataset": ({"datasets": ["toska"]}, "datasets", "did you mean 'tosca'"),
    "unknown nested key": ({"exports": {"zar": True}}, "exports.zar", "did you mean 'zarr'"),
    "duplicate list item": ({"setting": ["full_full", "full_full"]}, "setting", "more than once"),
}


@pytest.mark.parametrize("kind", sorted(KEY_KINDS))
def test_each_config_problem_is_one_line_with_key_and_fix(kind):
    override, key, words = KEY_KINDS[kind]
    base = {"synthetic": {"enabled": False}, "data_dir": "data", "annotations": "ann", "datasets": ["tosca"]}
    with pytest.raises(ConfigError) as info:
        resolve_config({**base, **override})
    lines = str(info.value).splitlines()
    assert len(lines) == 1, lines
    assert lines[0].startswith(f"{key}: ") and words in lines[0] and ". Fix: " in lines[0], lines[0]


def test_a_bad_config_prints_one_line_per_problem_and_no_traceback(becos_code, tmp_path):
    """One Snakemake run with five schema problems, one with the checks across keys (they run once the
    schema passes), one with `results` naming a file: every problem is one `becos config:` line."""
    schema_bad = {"min_overlapp": 0.2, "n_cam_pos": "ten", "cam_pos_regime": "hi", "caps": {"train": -1}, "n_chunks": 0}
    cross_bad = {"min_overlap": 0.8, "max_overlap": 0.2, "datasets": ["tosca", "toska"], "results": "taken"}
    for name, override, keys in (
        ("schema", schema_bad, ["min_overlapp", "n_cam_pos", "cam_pos_regime", "caps.train", "n_chunks"]),
        ("cross", cross_bad, ["min_overlap", "datasets", "results"]),
    ):
        workdir = write_config_file(tmp_path / name, tosca_config(becos_code, **override))
        (workdir / "taken").write_text("a file where the results folder should go\n")
        result = run_snakemake(tmp_path, "--cores", "1", workdir=workdir)
        text = result.stdout + result.stderr
        assert result.returncode != 0
        lines = problem_lines(text)
        assert sorted(line.split(": ")[1] for line in lines) == sorted(keys), text
        assert all(". Fix: " in line for line in lines), lines
        assert not any(marker in text for marker in NOT_SEEN), text
        assert not (workdir / "results").exists() and not (workdir / "logs").exists()


def test_a_plan_error_after_the_dataset_check_is_one_line(tmp_path):
    """`shapes` matching no shape is found when the plan is built, after the dataset check: inside the
    run (the check job just finished) and on the next run (the check is done). Both print the one
    `becos plan:` line with its fix, not Snakemake's InputFunctionException and traceback.
    The default configuration's small synthetic collection keeps the check short."""
    workdir = tmp_path / "run"
    line = "becos plan: shapes: no shape of datasets ['synthy', 'synthz'] matches ['synthy/nothing']. Fix: "
    for run in ("check runs", "check done"):
        result = run_snakemake(tmp_path, "-d", str(workdir), "--cores", "2", "--config", "shapes=[synthy/nothing]")
        assert result.returncode != 0, run
        assert line in result.stderr, (run, result.stderr[-3000:])
        assert not any(marker in result.stderr for marker in (*NOT_SEEN, "InputFunctionException")), run
    assert (workdir / "results" / "checks" / "datasets.json").exists()
    assert not (workdir / ".snakemake" / "locks").exists() or not any((workdir / ".snakemake" / "locks").iterdir())


def test_nested_command_line_values_are_typed_by_the_schema(tmp_path):
    """Issue #29: Snakemake reads the values inside a ``--config`` mapping as strings, so
    ``caps={train: 2}`` used to stop every run with ``caps.train: '2' is a string``: caps could not be set
    on the command line at all (its keys admit an integer or null). A real run of the rule writing the
    resolved configuration; a value that is no integer stays the one-line error."""
    import json

    workdir = write_config_file(tmp_path / "run", {"seed": 7})
    given = ("caps={train: 2, val: null, test: 0}", "exports={psmal: true}", "synthetic={fraction: 0.0625}")
    result = run_snakemake(tmp_path, "-d", str(workdir), "--cores", "1", "results/config.json", "--config", *given)
    assert result.returncode == 0, result.stderr[-3000:]
    resolved = json.loads((workdir / "results" / "config.json").read_text())
    assert resolved["caps"] == {"train": 2, "val": None, "test": 0} and resolved["exports"]["psmal"] is True
    # config/scale.yaml's size knob (issue #30): a number, merged into the synthetic block key by key
    assert resolved["synthetic"] == {
        "enabled": True,
        "out": "resources/synthetic",
        "seed": 0,
        "poses": 4,
        "fraction": 0.0625,
    }

    result = run_snakemake(tmp_path, "-d", str(workdir), "-n", "--cores", "1", "--config", "caps={train: two}")
    assert result.returncode != 0
    assert problem_lines(result.stderr) == [
        "becos config: caps.train: 'two' is a string, not an integer or null. Fix: give an integer or null "
        "(see config/README.md)"
    ], result.stderr[-3000:]
    base = {"synthetic": {"enabled": False}, "data_dir": "data", "annotations": "ann", "datasets": ["tosca"]}
    with pytest.raises(ConfigError, match=r"^caps.train: -1 is below the minimum 0\. Fix: use a value >= 0$"):
        resolve_config({**base, "caps": {"train": "-1"}})  # read as an integer, then checked like one
    assert resolve_config({**base, "evaluation": {"geodesics": "heat"}})["evaluation"]["geodesics"] == "heat"
    with pytest.raises(ConfigError, match=r"^seed: 'null' is a string, not an integer"):
        resolve_config({**base, "seed": "null"})  # top-level values: typed by Snakemake itself, not here


def test_config_file_faults_are_one_line_naming_the_file(tmp_path):
    """A YAML syntax error names file, line and column; a missing --configfile is one line (the default
    workflow profile reads the files before Snakemake does)."""
    bad = tmp_path / "bad.yaml"
    bad.write_text("seed: 3\ndatasets: [tosca\nn_chunks: 4\n")
    result = run_snakemake(tmp_path, "--configfile", str(bad), "--cores", "1")
    lines = problem_lines(result.stderr)
    assert result.returncode != 0 and len(lines) == 1, result.stderr
    assert lines[0].startswith(f"becos config: {bad}: line 3, column 9: not valid YAML") and "line 2" in lines[0]
    assert not any(marker in result.stderr for marker in NOT_SEEN), result.stderr

    result = run_snakemake(tmp_path, "--configfile=nothere.yaml", "--cores", "1")
    assert result.returncode != 0
    assert problem_lines(result.stderr) == [problem_lines(result.stderr)[0]]
    assert "nothere.yaml: config file not found" in result.stderr and "Traceback" not in result.stderr
    assert check_config_files(["--cores", "1", "--configfile", str(bad), "x.yaml", "--config", "a=1"])[1].startswith(
        "x.yaml: config file not found"
    )
    assert check_config_files(["--configfile", str(REPO / "config" / "tosca.yaml")]) == []


# --- failed jobs ------------------------------------------------------------------------------------
def test_error_lines_of_a_job_log():
    check = (
        "check: tosca: 76 shapes in /data/tosca-off\n"
        "becos check: the dataset check found 2 problem(s) (data_dir /data):\n"
        "  1. /data/tosca-off/cat0.off: truncated. Fix: re-download\n  2. /data/x: y. Fix: z\n\n"
    )
    assert error_lines(check) == check.splitlines()[1:4]
    report = "becos report: 6 pairs in s.zarr, rendering 2\nbecos report: s.zarr: no pairs. Fix: rebuild\n"
    assert error_lines(report) == report.splitlines()  # the trailing lines of the command
    bug = "becos remesh: note\nTraceback (most recent call last):\n  File \"x.py\", line 1\nKeyError: 'faces'\n"
    assert error_lines(bug)[0] == "KeyError: 'faces'"
    assert error_lines("step 1\nstep 2\nstep 3\nKilled\n") == ["step 2", "step 3", "Killed"]
    assert error_lines("") == []
    assert len(error_lines("becos x: a\n" + "  more\n" * 40)) == 12


def test_a_failed_job_shows_its_becos_error_line_on_the_console(becos_code, tmp_path):
    """A truncated TOSCA mesh in a copy of the data: the dataset check fails, and the console (not only
    logs/check_datasets.log) carries its `becos check:` line naming the file and the fix."""
    tosca = tmp_path / "data" / "tosca-off"
    tosca.mkdir(parents=True)
    for mesh in (becos_code / "data" / "tosca-off").glob("*.off"):
        (tosca / mesh.name).symlink_to(mesh)
    (tosca / "cat0.off").unlink()
    (tosca / "cat0.off").write_bytes((becos_code / "data" / "tosca-off" / "cat0.off").read_bytes()[:5000])
    workdir = write_config_file(tmp_path / "run", tosca_config(becos_code, data_dir=str(tmp_path / "data")))
    result = run_snakemake(tmp_path, "--cores", "1", "results/checks/datasets.json", workdir=workdir)
    assert result.returncode != 0
    log = (workdir / "logs" / "check_datasets.log").read_text()
    becos_lines = [line for line in log.splitlines() if line.startswith("becos check: ")]
    assert becos_lines, log
    console = result.stderr
    assert "becos: job check_datasets failed (log: logs/check_datasets.log):" in console, console[-3000:]
    for line in becos_lines:
        assert line in console
    assert "cat0.off" in console.split("becos: job check_datasets failed")[1]


def test_wrong_mesh_content_stops_the_run_before_any_remesh(becos_code, tmp_path):
    """Issue #17: a mesh replaced by a 3-vertex one, and a mesh holding another shape's content (dog0's
    25,290 vertices where the wolf class has 4,344), used to pass the dataset check and fail in
    ground_truth after every remesh had run. The check now names both, and no remesh job starts."""
    tosca = tmp_path / "data" / "tosca-off"
    tosca.mkdir(parents=True)
    for mesh in (becos_code / "data" / "tosca-off").glob("*.off"):
        (tosca / mesh.name).symlink_to(mesh)
    (tosca / "wolf1.off").unlink()
    (tosca / "wolf1.off").write_text("OFF\n3 1 0\n0 0 0\n1 0 0\n0 1 0.5\n3 0 1 2\n")
    (tosca / "wolf2.off").unlink()
    (tosca / "wolf2.off").symlink_to(becos_code / "data" / "tosca-off" / "dog0.off")
    config = tosca_config(becos_code, data_dir=str(tmp_path / "data"), shapes=["tosca/wolf*", "tosca/dog*"])
    workdir = write_config_file(tmp_path / "run", config)
    result = run_snakemake(tmp_path, "--cores", "1", workdir=workdir)
    assert result.returncode != 0
    console = result.stderr.split("becos: job check_datasets failed")[-1]
    assert f"{tosca / 'wolf1.off'}: all its 3 vertices lie in one plane" in console, console[-3000:]
    assert f"{tosca / 'wolf2.off'}: has 25290 vertices but its class template" in console
    assert not (workdir / "results" / "remeshed").exists() and not (workdir / "logs" / "remesh").exists()


def test_failure_report_names_rule_log_and_error(tmp_path):
    log = tmp_path / "remesh.log"
    log.write_text("remesh tosca/cat0 v0\nbecos remesh: /d/cat0.off: 3 vertices. Fix: re-download it\n")
    text = failure_report(
        [("remesh", "dataset=tosca, name=cat0", [str(log)]), ("catalog", "", [str(tmp_path / "never.log")])]
    )
    assert text.splitlines() == [
        f"becos: job remesh (dataset=tosca, name=cat0) failed (log: {log}):",
        "becos remesh: /d/cat0.off: 3 vertices. Fix: re-download it",
        f"becos: job catalog failed (log: {tmp_path / 'never.log'}):",
        f"(no log: {tmp_path / 'never.log'} was not written)",
    ]
    assert failure_report([]) == ""


# --- progress ---------------------------------------------------------------------------------------
def test_a_terminal_shows_the_progress_panel_and_plain_output_stays_available(tmp_path):
    """In a terminal the default profile draws the rich panel with done/total and an ETA; with
    BECOS_PROGRESS=plain (and whenever stderr is not a terminal) Snakemake's plain lines remain."""
    workdir = write_config_file(tmp_path / "run", {"seed": 7})
    code, screen = run_in_terminal(tmp_path, "-d", str(workdir), "--cores", "1", "results/config.json")
    assert code == 0, screen[-3000:]
    assert "Workflow Progress" in screen and "Total Progress" in screen, screen[-3000:]
    assert re.search(r"\b1/1\b", screen) and "ETA" in screen, screen[-3000:]
    assert "steps (100%) done" not in screen

    (workdir / "results" / "config.json").unlink()
    code, screen = run_in_terminal(
        tmp_path, "-d", str(workdir), "--cores", "1", "results/config.json", env={"BECOS_PROGRESS": "plain"}
    )
    assert code == 0, screen[-3000:]
    assert "Workflow Progress" not in screen and "1 of 1 steps (100%) done" in screen, screen[-3000:]


def test_the_published_benchmark_config_is_one_valid_configfile(becos_code, tmp_path):
    """config/becos.yaml (issue #30): the published benchmark's settings in one --configfile, valid
    against the schema and planned by a dry run: all eight datasets, the published lists and template
    table, and no partial_full (the reference publishes no list for it)."""
    import yaml

    repo = Path(__file__).resolve().parents[1]
    raw = yaml.safe_load((repo / "config" / "becos.yaml").read_text())
    assert raw["original_settings"] is True and raw["template_file"] == "templates_all.csv"
    assert sorted(raw["datasets"]) == sorted(
        p.stem for p in (repo / "becos" / "data" / "datasets").glob("*.yaml") if not p.stem.startswith("synth")
    )
    cmd = snakemake_cmd(
        None,
        "-d",
        str(tmp_path),
        "--configfile",
        str(repo / "config" / "becos.yaml"),
        "-n",
        "--cores",
        "2",
        "--config",
        f"data_dir={becos_code / 'data'}",
        f"annotations={becos_code}",
    )
    result = subprocess.run(cmd, capture_output=True, text=True)
    assert result.returncode == 0, result.stdout[-2000:] + result.stderr[-2000:]
    assert "check_datasets" in result.stdout + result.stderr


def test_every_sub_command_is_one_arguments_and_handler_pair(monkeypatch, capsys):
    """Each ``becos`` sub-command is one (arguments, handler) pair of its module's ``COMMANDS`` (issue #32,
    item 4): ``becos <name> --help`` prints its usage and its one-line description, and no module holds
    a pair that ``becos.cli.SUBCOMMANDS`` does not list."""
    import importlib

    from becos.cli import SUBCOMMANDS, main

    monkeypatch.setenv("COLUMNS", "250")  # argparse wraps at the terminal width: one line per description
    listed: dict[str, set[str]] = {}
    for name, module, help_text in SUBCOMMANDS:
        listed.setdefault(module, set()).add(name)
        arguments, run = importlib.import_module(module).COMMANDS[name]
        assert callable(arguments) and callable(run), name
        with pytest.raises(SystemExit) as exited:
            main([name, "--help"])
        out = capsys.readouterr().out
        assert exited.value.code == 0 and out.startswith(f"usage: becos {name} "), out
        if module not in ("becos.cli.baselines", "becos.cli.evaluate"):  # these two write a longer one
            assert f"\n{help_text[:1].upper()}{help_text[1:]}.\n" in out, out
    for module, names in listed.items():
        assert set(importlib.import_module(module).COMMANDS) == names, module


EXIT_HOOK = """
import atexit, os
MARK = os.environ["BECOS_TEST_EXIT_MARK"]
atexit.register(lambda: open(MARK + ".atexit", "w").close())


class _TornDown:
    def __del__(self, _open=open, _path=MARK + ".teardown"):  # when the interpreter tears modules down
        _open(_path, "w").close()


torn_down = _TornDown()
"""


def test_the_becos_program_runs_exit_handlers_and_skips_the_module_teardown(becos_code, tmp_path):
    """The ``becos`` program (its console script, as the workflow's jobs run it) ends without tearing its
    modules down (0.05-0.08 CPU-s per job): an ``atexit`` handler still runs and the whole output arrives,
    while an object that the teardown would finalise is not. The same command through :func:`becos.cli.main`
    and the interpreter's own exit finalises it (the marker works)."""
    hook = tmp_path / "hook"
    hook.mkdir()
    (hook / "sitecustomize.py").write_text(EXIT_HOOK)
    args = ["info", "--annotations", str(becos_code)]
    runs = {
        "program": [str(Path(sys.executable).with_name("becos")), *args],
        "interpreter": [sys.executable, "-c", f"import sys; from becos.cli import main; sys.exit(main({args!r}))"],
    }
    for name, cmd in runs.items():
        mark = tmp_path / name
        env = dict(os.environ, PYTHONPATH=os.pathsep.join([str(hook), os.environ.get("PYTHONPATH", "")]))
        result = subprocess.run(cmd, capture_output=True, text=True, env={**env, "BECOS_TEST_EXIT_MARK": str(mark)})
        assert result.returncode == 0, result.stderr[-2000:]
        assert json.loads(result.stdout)["nodes"] == 70, name
        assert Path(f"{mark}.atexit").exists(), name
        assert Path(f"{mark}.teardown").exists() == (name == "interpreter"), name


@pytest.mark.parametrize("profile", [None, "profiles/local", "profiles/slurm", "profiles/cluster-generic"])
def test_every_run_selects_jobs_greedily(profile, monkeypatch):
    """Snakemake's ILP job selector, and its sizing of every ready job's inputs each round, made
    Snakemake's own CPU grow faster than the job count at scale (issue #30; benchmarks/scheduler.py):
    the workflow profile, read beside any --profile, selects the greedy one among a bounded sample."""
    monkeypatch.chdir(REPO)
    from snakemake.cli import parse_args

    _, args = parse_args(["--cores", "2", "-n", *(("--profile", profile) if profile else ())])
    assert args.scheduler == "greedy"
    assert args.scheduler_subsample == 100
    _, args = parse_args(["--cores", "2", "-n", "--workflow-profile", "none"])
    assert args.scheduler == "ilp"  # Snakemake's own default: the profile's lines are what change it
    assert args.scheduler_subsample is None
