# Scoring: baselines predict on each store, `becos evaluate` scores every method of a setting together.


rule baseline:
    input:
        store=f"{RESULTS}/{{setting}}/benchmark.zarr",
        validation=f"{RESULTS}/{{setting}}/validation.json",
    output:
        directory(f"{RESULTS}/{{setting}}/predictions/{{baseline}}"),
    log:
        "logs/baseline/{setting}/{baseline}.log",
    wildcard_constraints:
        baseline="nn|zoomout",
    conda:
        "../envs/becos.yaml"
    resources:
        mem_mb=RESOURCES.mem_mb("baseline"),
        runtime=RESOURCES.runtime("baseline", n_pairs=setting_pairs),
    params:
        split=config["evaluation"]["split"],
    shell:
        "becos baseline {wildcards.baseline} {input.store:q} --out {output:q} --split {params.split} > {log:q} 2>&1"


rule evaluate:
    input:
        store=f"{RESULTS}/{{setting}}/benchmark.zarr",
        predictions=expand(f"{RESULTS}/{{{{setting}}}}/predictions/{{baseline}}", baseline=BASELINES),
    output:
        summary=report(f"{RESULTS}/{{setting}}/evaluation/summary.csv", category="Evaluation"),
        plot=report(f"{RESULTS}/{{setting}}/evaluation/pck.png", category="Evaluation"),
        per_pair=f"{RESULTS}/{{setting}}/evaluation/per_pair.csv",
    log:
        "logs/evaluate/{setting}.log",
    conda:
        "../envs/becos.yaml"
    resources:
        mem_mb=RESOURCES.mem_mb("evaluate"),
        runtime=RESOURCES.runtime("evaluate", n_pairs=setting_pairs),
    params:
        out=lambda w: f"{RESULTS}/{w.setting}/evaluation",
        split=config["evaluation"]["split"],
        geodesics=config["evaluation"]["geodesics"],
    shell:
        "becos evaluate {input.store:q} {input.predictions:q} --out {params.out:q} --split {params.split}"
        " --geodesics {params.geodesics} > {log:q} 2>&1"
