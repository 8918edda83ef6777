# Scoring: baselines predict on each store, `becos evaluate` scores every method of a setting together.


rule baseline:
    input:
        store=rules.zarr_store.output[0],
        gate=rules.validate_store.output[0],  # a gate only: the store passed its validation
    output:
        directory(str(LAYOUT.predictions("{setting}", "{baseline}"))),
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
        store=rules.zarr_store.output[0],
        predictions=expand(str(LAYOUT.predictions("{{setting}}", "{baseline}")), baseline=BASELINES),
    output:
        # the file names `becos evaluate` writes into its --out folder
        summary=report(str(LAYOUT.evaluation("{setting}") / "summary.csv"), category="Evaluation"),
        plot=report(str(LAYOUT.evaluation("{setting}") / "pck.png"), category="Evaluation"),
        per_pair=LAYOUT.evaluation("{setting}") / "per_pair.csv",
    log:
        "logs/evaluate/{setting}.log",
    conda:
        "../envs/becos.yaml"
    resources:
        mem_mb=RESOURCES.mem_mb("evaluate"),
        runtime=RESOURCES.runtime("evaluate", n_pairs=setting_pairs),
    params:
        out=lambda w: str(LAYOUT.evaluation(w.setting)),
        split=config["evaluation"]["split"],
        geodesics=config["evaluation"]["geodesics"],
    shell:
        "becos evaluate {input.store:q} {input.predictions:q} --out {params.out:q} --split {params.split}"
        " --geodesics {params.geodesics} > {log:q} 2>&1"
