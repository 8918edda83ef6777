# Stage 1-2: the input data (built-in collection or downloads), the dataset check, the catalog.


rule resolved_config:
    conda:
        "../envs/becos.yaml"
    output:
        LAYOUT.config,
    params:
        config=json.dumps(config, sort_keys=True),
    log:
        "logs/resolved_config.log",
    shell:
        "becos write-config --options {params.config:q} --out {output:q} > {log:q} 2>&1"


if config["synthetic"]["enabled"]:

    rule synthetic_collection:
        conda:
            "../envs/becos.yaml"
        output:
            directory(config["synthetic"]["out"]),
        params:
            seed=config["synthetic"]["seed"],
            poses=config["synthetic"]["poses"],
        resources:
            mem_mb=RESOURCES.mem_mb("synthetic_collection"),
            runtime=RESOURCES.runtime("synthetic_collection"),
        log:
            "logs/synthetic_collection.log",
        shell:
            "becos synthetic {output:q} --seed {params.seed} --poses {params.poses} > {log:q} 2>&1"


if config["annotations_archive"]:

    rule fetch_annotations:
        conda:
            "../envs/becos.yaml"
        output:
            directory(config["annotations"]),
        params:
            url=config["annotations_archive"]["url"],
            sha256=config["annotations_archive"]["sha256"],
        log:
            "logs/fetch_annotations.log",
        shell:
            "becos fetch-annotations --url {params.url:q} --sha256 {params.sha256} --dest {output:q} > {log:q} 2>&1"


# DeformingThings4D: one job per class of each enabled dt4d dataset whose DATA/DeformingThings4D/<kind>
# and info file exist at planning time (becos.dt4d.preparation_plan). Output: the class's stamp, which
# records each .anime's size, mtime and sha256 (update(): Snakemake must not delete it before the job,
# so the job rewrites only the OBJs whose .anime changed). The info file is ancient() and the class's
# own entry a parameter: editing one class's entry (or adding a class) reruns that class only.
DT4D_JOBS = {(job.kind, job.cls): job for job in bdt4d.preparation_plan(config)}

if DT4D_JOBS:

    rule prepare_dt4d:
        conda:
            "../envs/becos.yaml"
        input:
            anime=lambda w: DT4D_JOBS[(w.kind, w.cls)].anime,
            info=lambda w: ancient(DT4D_JOBS[(w.kind, w.cls)].info),
        output:
            update(str(Path(config["data_dir"]) / "dt4d_{kind}" / "{cls}" / bdt4d.STAMP_NAME)),
        wildcard_constraints:
            kind="animals|humanoids",
            cls="[^/]+",
        params:
            data_dir=config["data_dir"],
            listing=lambda w: DT4D_JOBS[(w.kind, w.cls)].listing,
        resources:
            mem_mb=RESOURCES.mem_mb("prepare_dt4d"),
            runtime=RESOURCES.runtime("prepare_dt4d"),
        log:
            "logs/prepare_dt4d/{kind}/{cls}.log",
        shell:
            "becos prepare-dt4d --data-dir {params.data_dir:q} --info {input.info:q} --kind {wildcards.kind}"
            " --classes {wildcards.cls:q} > {log:q} 2>&1"


if config["download"]:

    # opt-in downloads of the public dataset archives (kids, shrec20): one job per dataset, before the
    # dataset check; on the machine that runs Snakemake (cluster nodes often have no internet)
    localrules:
        download_dataset,

    rule download_dataset:
        conda:
            "../envs/becos.yaml"
        output:
            str(LAYOUT.downloaded("{dataset}")),
        wildcard_constraints:
            dataset="|".join(config["download"]),
        params:
            data_dir=config["data_dir"],
            url=lambda wildcards: archive_url(wildcards.dataset, config["download_urls"]),
        resources:
            mem_mb=RESOURCES.mem_mb("download_dataset"),
            runtime=RESOURCES.runtime("download_dataset"),
        log:
            "logs/download/{dataset}.log",
        shell:
            "becos download-dataset {wildcards.dataset} --data-dir {params.data_dir:q} --url {params.url:q}"
            " --out {output:q} > {log:q} 2>&1"


checkpoint check_datasets:
    conda:
        "../envs/becos.yaml"
    input:
        generated_inputs,
    output:
        LAYOUT.checks,
    params:
        datasets=" ".join(config["datasets"]),
        data_dir=config["data_dir"],
        annotations=config["annotations"],
        template_file=config["template_file"],
        geometry="" if config["check_geometry"] else "--no-geometry-check",
    log:
        "logs/check_datasets.log",
    shell:
        "becos check --datasets {params.datasets} --data-dir {params.data_dir:q}"
        " --annotations {params.annotations:q} --template-table {params.template_file:q} {params.geometry}"
        " --out {output:q} > {log:q} 2>&1"


rule catalog:
    conda:
        "../envs/becos.yaml"
    input:
        LAYOUT.checks,
    output:
        LAYOUT.catalog,
    params:
        options=bw.job_options(config, "catalog"),
    log:
        "logs/catalog.log",
    shell:
        "becos catalog --options {params.options:q} --out {output:q} > {log:q} 2>&1"
