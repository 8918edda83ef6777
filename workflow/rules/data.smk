# Stage 1-2: the input data (built-in collection or downloads), the dataset check, the catalog.


rule resolved_config:
    output:
        LAYOUT.config,
    params:
        config=json.dumps(config, sort_keys=True),
    log:
        "logs/resolved_config.log",
    shell:
        "becos write-config --options {params.config:q} --out {output} > {log} 2>&1"


if config["synthetic"]["enabled"]:

    rule synthetic_collection:
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
            "becos synthetic {output} --seed {params.seed} --poses {params.poses} > {log} 2>&1"


if config["annotations_archive"]:

    rule fetch_annotations:
        output:
            directory(config["annotations"]),
        params:
            url=config["annotations_archive"]["url"],
            sha256=config["annotations_archive"]["sha256"],
        log:
            "logs/fetch_annotations.log",
        shell:
            "becos fetch-annotations --url {params.url:q} --sha256 {params.sha256} --dest {output} > {log} 2>&1"


if config["download"]:

    # opt-in downloads of the public dataset archives (kids, shrec20): one job per dataset, before the
    # dataset check; on the machine that runs Snakemake (cluster nodes often have no internet)
    localrules:
        download_dataset,

    rule download_dataset:
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
            " --out {output} > {log} 2>&1"


checkpoint check_datasets:
    input:
        generated_inputs,
    output:
        LAYOUT.checks,
    params:
        datasets=" ".join(config["datasets"]),
        data_dir=config["data_dir"],
        annotations=config["annotations"],
        template_file=config["template_file"],
    log:
        "logs/check_datasets.log",
    shell:
        "becos check --datasets {params.datasets} --data-dir {params.data_dir:q}"
        " --annotations {params.annotations:q} --template-table {params.template_file:q}"
        " --out {output} > {log} 2>&1"


rule catalog:
    input:
        LAYOUT.checks,
    output:
        LAYOUT.catalog,
    params:
        options=bw.job_options(config, "catalog"),
    log:
        "logs/catalog.log",
    shell:
        "becos catalog --options {params.options:q} --out {output} > {log} 2>&1"
