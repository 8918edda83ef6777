# becos: full and partial shape-matching benchmarks with exact ground truth.
#   snakemake --cores 2                       build what config/config.yaml asks for
#   snakemake --cores 2 --configfile my.yaml  another configuration (keys: config/README.md)
#   snakemake --profile profiles/local        the laptop profile
import os

from snakemake.utils import min_version, validate

min_version("9.0")


# the default configuration lives beside this Snakefile, whatever the working directory (-d)
configfile: os.path.join(workflow.basedir, "config", "config.yaml")


validate(config, "config/schema.yaml")


include: "workflow/rules/common.smk"
include: "workflow/rules/data.smk"
include: "workflow/rules/pairs.smk"
include: "workflow/rules/export.smk"
include: "workflow/rules/evaluate.smk"


rule all:
    default_target: True
    input:
        all_targets,
