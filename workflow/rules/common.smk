# Shared names and the plan. Every job runs `becos <sub-command>` from the environment that runs
# Snakemake (its bin folder goes first on PATH): the pip-installed environment is the only one.
import json
import os
import sys
from pathlib import Path

from becos import workflow as bw

config.update(bw.resolve_config(config))
SETTINGS = bw.settings_of(config)
LAYOUT = bw.Layout.of(config)
RESULTS = str(LAYOUT.results)
EXPORTS = config["exports"]
BASELINES = config["evaluation"]["baselines"]


envvars:
    "PATH",


os.environ["PATH"] = os.pathsep.join([str(Path(sys.executable).parent), os.environ.get("PATH", "")])

_plans = {}


def plan():
    """The catalog, manifests and job lists; known once the dataset check has run."""
    checkpoints.check_datasets.get()
    if "plan" not in _plans:
        _plans["plan"] = bw.Plan.build(config)
    return _plans["plan"]


def chunk_files(setting, kind):
    """Index files of every chunk of a setting (kind: ground_truth or pairs)."""
    p = plan()
    path = LAYOUT.ground_truth_index if kind == "ground_truth" else LAYOUT.pairs_index
    return [str(path(setting, c)) for c in p.chunks(setting)]


def all_targets(wildcards):
    targets = [str(LAYOUT.config)]
    for setting in SETTINGS:
        base = f"{RESULTS}/{setting}"
        targets.append(f"{base}/validation.json")
        if EXPORTS["released"]:
            targets.append(f"{base}/released")
        if EXPORTS["psmal"]:
            targets.append(f"{base}/psmal")
        if EXPORTS["published_pickle"]:
            targets.append(f"{base}/pairings_{setting}.pkl")
        if EXPORTS["report"]:
            targets.append(f"{base}/report")
        if BASELINES:
            targets.append(f"{base}/evaluation/summary.csv")
    return targets


def generated_inputs(wildcards):
    inputs = []
    if config["synthetic"]["enabled"]:
        inputs.append(config["synthetic"]["out"])
    if config["annotations_archive"]:
        inputs.append(config["annotations"])
    return inputs
