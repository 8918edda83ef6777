# Stage 5-7: the Zarr store per setting, its validation, the other export formats, the report.


rule store_metadata:
    output:
        LAYOUT.metadata("{setting}"),
    log:
        "logs/store_metadata/{setting}.log",
    conda:
        "../envs/becos.yaml"
    params:
        # the rerun trigger: the keys of the stages whose output a store holds (becos.workflow.store_keys); an
        # edit to another (e.g. n_renders) reruns the report, not every store
        store_keys=bw.store_keys(config),
        # what the metadata records: the whole config. A param computed from the output is "derived", and
        # Snakemake leaves derived params out of its params trigger
        config=lambda wildcards, output: json.dumps(config, sort_keys=True),
    shell:
        "becos metadata --options {params.config:q} --setting {wildcards.setting} --out {output:q} > {log:q} 2>&1"


# The pair records leave out what their ground-truth and remesh files give back exactly
# (becos.build.record_sources): the store job reads those too, so they are its inputs.
rule zarr_store:
    input:
        pairs=lambda w: chunk_files(w.setting, "pairs"),
        metadata=rules.store_metadata.output[0],
        ground_truth=lambda w: chunk_files(w.setting, "ground_truth"),
        remeshed=lambda w: plan().setting_inputs(w.setting),
    output:
        directory(str(LAYOUT.store("{setting}"))),
    log:
        "logs/zarr_store/{setting}.log",
    conda:
        "../envs/becos.yaml"
    threads: RESOURCES.threads("zarr_store")
    resources:
        mem_mb=RESOURCES.mem_mb("zarr_store"),
        runtime=RESOURCES.runtime("zarr_store", n_pairs=setting_pairs),
    shell:
        "becos export-zarr --setting {wildcards.setting} --out {output:q} --metadata {input.metadata:q}"
        " --processes {threads} {input.pairs:q} > {log:q} 2>&1"


rule validate_store:
    input:
        rules.zarr_store.output[0],
    output:
        LAYOUT.validation("{setting}"),
    log:
        "logs/validate_store/{setting}.log",
    conda:
        "../envs/becos.yaml"
    threads: RESOURCES.threads("validate_store")
    resources:
        mem_mb=RESOURCES.mem_mb("validate_store"),
        runtime=RESOURCES.runtime("validate_store", n_pairs=setting_pairs),
    shell:
        "becos validate {input:q} --threads {threads} --json {output:q} > {log:q} 2>&1"


rule released_layout:
    input:
        store=rules.zarr_store.output[0],
        gate=rules.validate_store.output[0],  # a gate only: the store passed its validation
    output:
        directory(str(LAYOUT.released("{setting}"))),
    log:
        "logs/released_layout/{setting}.log",
    conda:
        "../envs/becos.yaml"
    resources:
        mem_mb=RESOURCES.mem_mb("released_layout"),
        runtime=RESOURCES.runtime("released_layout", n_pairs=setting_pairs),
    shell:
        "becos export-released {input.store:q} {output:q} > {log:q} 2>&1"


rule psmal_layout:
    input:
        store=rules.zarr_store.output[0],
        gate=rules.validate_store.output[0],  # a gate only: the store passed its validation
    output:
        directory(str(LAYOUT.psmal("{setting}"))),
    log:
        "logs/psmal_layout/{setting}.log",
    conda:
        "../envs/becos.yaml"
    resources:
        mem_mb=RESOURCES.mem_mb("psmal_layout"),
        runtime=RESOURCES.runtime("psmal_layout", n_pairs=setting_pairs),
    shell:
        "becos export-psmal {input.store:q} {output:q} > {log:q} 2>&1"


# ULRSSM's layout without dist/ (no geodesics: `becos export-ulrssm STORE OUT --geodesics` by hand writes
# them; config/README.md, docs/released-layout.md section 5)
rule ulrssm_layout:
    input:
        store=rules.zarr_store.output[0],
        gate=rules.validate_store.output[0],  # a gate only: the store passed its validation
    output:
        directory(str(LAYOUT.ulrssm("{setting}"))),
    log:
        "logs/ulrssm_layout/{setting}.log",
    conda:
        "../envs/becos.yaml"
    resources:
        mem_mb=RESOURCES.mem_mb("ulrssm_layout"),
        runtime=RESOURCES.runtime("ulrssm_layout", n_pairs=setting_pairs),
    shell:
        "becos export-ulrssm {input.store:q} {output:q} > {log:q} 2>&1"


rule dpfm_layout:
    input:
        store=rules.zarr_store.output[0],
        gate=rules.validate_store.output[0],  # a gate only: the store passed its validation
    output:
        directory(str(LAYOUT.dpfm("{setting}"))),
    log:
        "logs/dpfm_layout/{setting}.log",
    conda:
        "../envs/becos.yaml"
    resources:
        mem_mb=RESOURCES.mem_mb("dpfm_layout"),
        runtime=RESOURCES.runtime("dpfm_layout", n_pairs=setting_pairs),
    shell:
        "becos export-dpfm {input.store:q} {output:q} > {log:q} 2>&1"


from becos.products.geodesic_jobs import WORKFLOW_PARTS as GEODESIC_PARTS

GEODESIC_SPLITS = " ".join(["--splits", *EXPORTS["geodesic_splits"]]) if EXPORTS["geodesic_splits"] else ""


# Geodesics (docs/released-layout.md section 3): one plan over every setting's store, so that a full mesh
# shared by pairs and settings is solved once; GEODESIC_PARTS jobs solve its meshes; one job per setting
# writes the loaders' layouts from their rows (the rows are temporary).
rule geodesic_plan:
    input:
        stores=[str(LAYOUT.store(s)) for s in SETTINGS],
        gate=[str(LAYOUT.validation(s)) for s in SETTINGS],  # gates only: the stores passed validation
    output:
        temp(directory(str(LAYOUT.geodesic_plan))),
    log:
        "logs/geodesics/plan.log",
    conda:
        "../envs/becos.yaml"
    resources:
        mem_mb=RESOURCES.mem_mb("geodesic_plan"),
        runtime=RESOURCES.runtime("geodesic_plan"),
        disk_mb=lambda wildcards: geodesics_disk_mb(),
    params:
        splits=GEODESIC_SPLITS,
        parts=GEODESIC_PARTS,
    shell:
        "becos geodesic-plan {input.stores:q} --out {output:q} --parts {params.parts} {params.splits} > {log:q} 2>&1"


rule geodesic_rows:
    input:
        rules.geodesic_plan.output[0],
    output:
        temp(directory(str(LAYOUT.geodesic_rows("{part}")))),
    log:
        "logs/geodesics/rows_{part}.log",
    conda:
        "../envs/becos.yaml"
    resources:
        mem_mb=RESOURCES.mem_mb("geodesic_rows"),
        runtime=RESOURCES.runtime("geodesic_rows"),
    shell:
        "becos geodesic-rows {input:q}/part_{wildcards.part}.npz {output:q} > {log:q} 2>&1"


rule geodesics:
    input:
        store=rules.zarr_store.output[0],
        gate=rules.validate_store.output[0],  # a gate only: the store passed its validation
        rows=[str(LAYOUT.geodesic_rows(part)) for part in range(GEODESIC_PARTS)],
    output:
        directory(str(LAYOUT.geodesics("{setting}"))),
    log:
        "logs/geodesics/{setting}.log",
    conda:
        "../envs/becos.yaml"
    resources:
        mem_mb=RESOURCES.mem_mb("geodesics"),
        runtime=RESOURCES.runtime("geodesics", n_pairs=setting_pairs),
    params:
        splits=GEODESIC_SPLITS,
        layouts=" ".join(EXPORTS["geodesic_layouts"]),
    shell:
        "becos export-geodesics {input.store:q} {output:q} {params.splits} --layouts {params.layouts}"
        " --rows {input.rows:q} > {log:q} 2>&1"


rule published_pairings:
    input:
        manifest=rules.manifest.output[0],
        catalog=LAYOUT.catalog,
        store=rules.zarr_store.output[0],
    output:
        LAYOUT.published_pickle("{setting}"),
    log:
        "logs/published_pairings/{setting}.log",
    conda:
        "../envs/becos.yaml"
    params:
        options=bw.job_options(config, "export"),
    shell:
        "becos export-pairings --options {params.options:q} --setting {wildcards.setting} --store {input.store:q}"
        " --manifest {input.manifest:q} --catalog {input.catalog:q} --out {output:q} > {log:q} 2>&1"


rule report:
    input:
        store=rules.zarr_store.output[0],
        gate=rules.validate_store.output[0],  # a gate only: the store passed its validation
    output:
        report(
            directory(str(LAYOUT.report("{setting}"))),
            htmlindex="index.html",
            caption="../report/index.rst",
            category="Benchmark report",
            labels={"setting": "{setting}"},
        ),
    log:
        "logs/report/{setting}.log",
    conda:
        "../envs/becos.yaml"
    resources:
        mem_mb=RESOURCES.mem_mb("report"),
        runtime=RESOURCES.runtime("report", n_pairs=setting_pairs),
    params:
        renders=config["n_renders"] if config["store_vis"] else 0,
    shell:
        "becos report {input.store:q} {output:q} --renders {params.renders} > {log:q} 2>&1"
