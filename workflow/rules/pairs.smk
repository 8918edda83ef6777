# Stage 3-4: pair manifests, remeshing per shape variant, ground truth and pair records per chunk.


rule manifest:
    input:
        catalog=LAYOUT.catalog,
        config=ancient(LAYOUT.config),
    output:
        f"{RESULTS}/{{setting}}/manifest.csv",
    params:
        options=bw.digest(bw.stage_options(config, "manifest")),
    log:
        "logs/manifest/{setting}.log",
    shell:
        "becos manifest --config {input.config} --setting {wildcards.setting}"
        " --catalog {input.catalog} --out {output} > {log} 2>&1"


rule remesh:
    input:
        mesh=lambda w: plan().files[(w.dataset, w.name)],
        catalog=ancient(LAYOUT.catalog),
        config=ancient(LAYOUT.config),
    output:
        npz=f"{RESULTS}/remeshed/{{dataset}}/{{name}}/{{token}}.npz",
        ply=f"{RESULTS}/remeshed/{{dataset}}/{{name}}/{{token}}.ply",
    params:
        target=lambda w: plan().remesh_target(w.dataset, w.name, w.token),
        shape=lambda w: plan().shape_digest(w.dataset, w.name),
    wildcard_constraints:
        dataset="[a-z0-9_]+",
        name=".+",
        token="v[0-9]+|f[0-9]+",
    resources:
        mem_mb=3000,
        runtime=20,
    log:
        "logs/remesh/{dataset}/{name}/{token}.log",
    shell:
        "becos remesh --config {input.config} --dataset {wildcards.dataset:q} --name {wildcards.name:q}"
        " --token {wildcards.token} --out {output.npz} --ply {output.ply} > {log} 2>&1"


rule ground_truth:
    input:
        manifest=ancient(f"{RESULTS}/{{setting}}/manifest.csv"),
        catalog=ancient(LAYOUT.catalog),
        config=ancient(LAYOUT.config),
        remeshed=lambda w: plan().chunk_inputs(w.setting, int(w.chunk)),
    output:
        f"{RESULTS}/{{setting}}/ground_truth/chunk_{{chunk}}.json",
    params:
        rows=lambda w: plan().chunk_digest(w.setting, int(w.chunk), "ground_truth"),
    wildcard_constraints:
        chunk="[0-9]{4}",
    resources:
        mem_mb=6000,
        runtime=120,
    log:
        "logs/ground_truth/{setting}/{chunk}.log",
    shell:
        "becos ground-truth --config {input.config} --setting {wildcards.setting} --chunk {wildcards.chunk}"
        " --out {output} > {log} 2>&1"


rule pairs:
    input:
        ground_truth=f"{RESULTS}/{{setting}}/ground_truth/chunk_{{chunk}}.json",
        manifest=ancient(f"{RESULTS}/{{setting}}/manifest.csv"),
        catalog=ancient(LAYOUT.catalog),
        config=ancient(LAYOUT.config),
        remeshed=lambda w: plan().chunk_inputs(w.setting, int(w.chunk)),
    output:
        f"{RESULTS}/{{setting}}/pairs/chunk_{{chunk}}.json",
    params:
        rows=lambda w: plan().chunk_digest(w.setting, int(w.chunk), "pairs"),
    wildcard_constraints:
        chunk="[0-9]{4}",
    resources:
        mem_mb=4000,
        runtime=120,
    log:
        "logs/pairs/{setting}/{chunk}.log",
    shell:
        "becos pairs --config {input.config} --setting {wildcards.setting} --chunk {wildcards.chunk}"
        " --ground-truth {input.ground_truth} --out {output} > {log} 2>&1"
