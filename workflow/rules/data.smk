# Stage 1-2: the input data (built-in collection or downloads), the dataset check, the catalog.


rule resolved_config:
    output:
        LAYOUT.config,
    log:
        "logs/resolved_config.log",
    conda:
        "../envs/becos.yaml"
    params:
        config=json.dumps(config, sort_keys=True),
    shell:
        "becos write-config --options {params.config:q} --out {output:q} > {log:q} 2>&1"


if config["synthetic"]["enabled"]:

    rule synthetic_collection:
        output:
            directory(config["synthetic"]["out"]),
        log:
            "logs/synthetic_collection.log",
        conda:
            "../envs/becos.yaml"
        resources:
            mem_mb=RESOURCES.mem_mb("synthetic_collection"),
            runtime=RESOURCES.runtime("synthetic_collection"),
        params:
            seed=config["synthetic"]["seed"],
            size=(
                f"--poses {config['synthetic']['poses']}"
                if config["synthetic"]["fraction"] is None
                else f"--fraction {config['synthetic']['fraction']}"
            ),
        shell:
            "becos synthetic {output:q} --seed {params.seed} {params.size} > {log:q} 2>&1"


if config["annotations_archive"]:

    rule fetch_annotations:
        output:
            directory(config["annotations"]),
        log:
            "logs/fetch_annotations.log",
        conda:
            "../envs/becos.yaml"
        params:
            url=config["annotations_archive"]["url"],
            sha256=config["annotations_archive"]["sha256"],
        shell:
            "becos fetch-annotations --url {params.url:q} --sha256 {params.sha256} --dest {output:q} > {log:q} 2>&1"


# DeformingThings4D: one job per class of each enabled dt4d dataset whose DATA/DeformingThings4D/<kind>
# and info file exist at planning time (becos.sources.dt4d.preparation_plan). Output: the class's stamp, which
# records each .anime's size, mtime and sha256 (update(): Snakemake must not delete it before the job,
# so the job rewrites only the OBJs whose .anime changed). The info file is ancient() and the class's
# own entry a parameter: editing one class's entry (or adding a class) reruns that class only.
DT4D_JOBS = {
    (job.kind, job.cls): job
    for job in bdt4d.preparation_plan(config["data_dir"], config["datasets"], config["annotations"])
}

if DT4D_JOBS:

    rule prepare_dt4d:
        input:
            anime=lambda w: DT4D_JOBS[(w.kind, w.cls)].anime,
            info=lambda w: ancient(DT4D_JOBS[(w.kind, w.cls)].info),
        output:
            update(str(Path(config["data_dir"]) / "dt4d_{kind}" / "{cls}" / bdt4d.STAMP_NAME)),
        log:
            "logs/prepare_dt4d/{kind}/{cls}.log",
        wildcard_constraints:
            kind="animals|humanoids",
            cls="[^/]+",
        group:
            "dt4d"
        conda:
            "../envs/becos.yaml"
        resources:
            mem_mb=RESOURCES.mem_mb("prepare_dt4d"),
            runtime=RESOURCES.runtime("prepare_dt4d"),
        params:
            data_dir=config["data_dir"],
            listing=lambda w: DT4D_JOBS[(w.kind, w.cls)].listing,
        shell:
            "becos prepare-dt4d --data-dir {params.data_dir:q} --info {input.info:q} --kind {wildcards.kind}"
            " --classes {wildcards.cls:q} --anime {input.anime:q} > {log:q} 2>&1"


if config["download"]:

    # opt-in downloads of the public dataset archives (kids, shrec20): one job per dataset, before the
    # dataset check; on the machine that runs Snakemake (cluster nodes often have no internet)
    localrules:
        download_dataset,

    rule download_dataset:
        output:
            str(LAYOUT.downloaded("{dataset}")),
        log:
            "logs/download/{dataset}.log",
        wildcard_constraints:
            dataset="|".join(config["download"]),
        conda:
            "../envs/becos.yaml"
        resources:
            mem_mb=RESOURCES.mem_mb("download_dataset"),
            runtime=RESOURCES.runtime("download_dataset"),
        params:
            data_dir=config["data_dir"],
            url=lambda wildcards: archive_url(wildcards.dataset, config["download_urls"]),
        shell:
            "becos download-dataset {wildcards.dataset} --data-dir {params.data_dir:q} --url {params.url:q}"
            " --out {output:q} > {log:q} 2>&1"


checkpoint check_datasets:
    input:
        # gates only: what the run generates or downloads must be in place first; the check reads it
        # through the folders it is passed (data_dir, annotations)
        gate=generated_inputs,
    output:
        LAYOUT.checks,
    log:
        "logs/check_datasets.log",
    conda:
        "../envs/becos.yaml"
    threads: RESOURCES.threads("check_datasets")
    params:
        # a rerun trigger only: the content of every file the check reads (becos.workflow.digests), so a
        # mesh or annotation file replaced after a finished run is checked again, whatever its time
        inputs=lambda w: inputs_digest(),
        datasets=" ".join(config["datasets"]),
        data_dir=config["data_dir"],
        annotations=config["annotations"],
        template_file=config["template_file"],
        geometry="" if config["check_geometry"] else "--no-geometry-check",
    shell:
        "becos check --datasets {params.datasets} --data-dir {params.data_dir:q}"
        " --annotations {params.annotations:q} --template-table {params.template_file:q} {params.geometry}"
        " --processes {threads} --out {output:q} > {log:q} 2>&1"


rule catalog:
    input:
        gate=LAYOUT.checks,  # a gate only: the catalog is made of checked datasets
    output:
        LAYOUT.catalog,
    log:
        "logs/catalog.log",
    # under a second, and every ground-truth job waits for it: run it before the remesh jobs, not after
    priority: 1
    conda:
        "../envs/becos.yaml"
    params:
        options=bw.job_options(config, "catalog"),
        inputs=lambda w: inputs_digest(),  # a rerun trigger only, as for check_datasets
        data_dir=config["data_dir"],
        annotations=config["annotations"],
    shell:
        "becos catalog --options {params.options:q} --data-dir {params.data_dir:q}"
        " --annotations {params.annotations:q} --out {output:q} > {log:q} 2>&1"
