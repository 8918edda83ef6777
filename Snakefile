# becos: full and partial shape-matching benchmarks with exact ground truth.
#   snakemake --cores 2                       build what config/config.yaml asks for
#   snakemake --cores 2 --configfile my.yaml  another configuration (keys: config/README.md)
#   snakemake --profile profiles/local        the laptop profile
import os
import sys

from snakemake.utils import min_version

from becos.errors import ConfigError
from becos.workflow import resolve_config

min_version("9.0")


# the default configuration lives beside this Snakefile, whatever the working directory (-d)
configfile: os.path.join(workflow.basedir, "config", "config.yaml")


# becos/data/schema.yaml and the checks across keys (defaults filled in); each problem is one console line
# `becos config: <key>: <what is wrong>. Fix: <fix>`, without Snakemake's traceback header
try:
    config.update(resolve_config(config))
except ConfigError as exc:
    sys.exit("\n".join(f"becos config: {line}" for line in str(exc).splitlines()))


# `snakemake --report report.zip`: each setting's report folder (rule report) under this description
report: "workflow/report/workflow.rst"


include: "workflow/rules/common.smk"
include: "workflow/rules/data.smk"
include: "workflow/rules/pairs.smk"
include: "workflow/rules/export.smk"
include: "workflow/rules/evaluate.smk"


rule all:
    default_target: True
    input:
        all_targets,
