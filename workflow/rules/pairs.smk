# Stage 3-4: pair manifests, remeshing per shape variant, ground truth and pair records per chunk.
# A remesh job gets its shape's catalog row as a parameter (not the catalog file), so rewriting the
# catalog never reruns a remesh; a chunk job reruns whenever the manifest is rewritten, but keeps
# every pair file whose input key is unchanged (becos.workflow).


rule manifest:
    input:
        catalog=LAYOUT.catalog,
    output:
        f"{RESULTS}/{{setting}}/manifest.csv",
    log:
        "logs/manifest/{setting}.log",
    conda:
        "../envs/becos.yaml"
    params:
        options=bw.job_options(config, "manifest"),
    shell:
        "becos manifest --options {params.options:q} --setting {wildcards.setting}"
        " --catalog {input.catalog:q} --out {output:q} > {log:q} 2>&1"


rule remesh:
    input:
        lambda w: plan().files[(w.dataset, w.name)],
    output:
        npz=f"{RESULTS}/remeshed/{{dataset}}/{{name}}/{{token}}.npz",
        ply=f"{RESULTS}/remeshed/{{dataset}}/{{name}}/{{token}}.ply",
    log:
        "logs/remesh/{dataset}/{name}/{token}.log",
    wildcard_constraints:
        dataset="[a-z0-9_]+",
        name=".+",
        token="v[0-9]+|f[0-9]+",
    conda:
        "../envs/becos.yaml"
    resources:
        mem_mb=RESOURCES.mem_mb("remesh"),
        runtime=RESOURCES.runtime("remesh"),
    params:
        target=lambda w: plan().remesh_target(w.dataset, w.name, w.token),
        shape=lambda w: plan().shape_json(w.dataset, w.name),
        options=bw.job_options(config, "remesh"),
    shell:
        "becos remesh --options {params.options:q} --shape {params.shape:q}"
        " --token {wildcards.token} --out {output.npz:q} --ply {output.ply:q} > {log:q} 2>&1"


rule ground_truth:
    input:
        manifest=f"{RESULTS}/{{setting}}/manifest.csv",
        catalog=LAYOUT.catalog,
        remeshed=lambda w: plan().chunk_inputs(w.setting, int(w.chunk)),
        edges=lambda w: plan().chunk_edge_files(w.setting, int(w.chunk)),
    output:
        f"{RESULTS}/{{setting}}/ground_truth/chunk_{{chunk}}.json",
    log:
        "logs/ground_truth/{setting}/{chunk}.log",
    wildcard_constraints:
        chunk="[0-9]{4}",
    conda:
        "../envs/becos.yaml"
    resources:
        mem_mb=RESOURCES.mem_mb("ground_truth"),
        runtime=RESOURCES.runtime("ground_truth", n_pairs=chunk_pairs),
    params:
        options=bw.job_options(config, "ground_truth"),
    shell:
        "becos ground-truth --options {params.options:q} --setting {wildcards.setting} --chunk {wildcards.chunk}"
        " --out {output:q} > {log:q} 2>&1"


rule pairs:
    input:
        ground_truth=f"{RESULTS}/{{setting}}/ground_truth/chunk_{{chunk}}.json",
        manifest=f"{RESULTS}/{{setting}}/manifest.csv",
        catalog=LAYOUT.catalog,
        remeshed=lambda w: plan().chunk_inputs(w.setting, int(w.chunk)),
    output:
        f"{RESULTS}/{{setting}}/pairs/chunk_{{chunk}}.json",
    log:
        "logs/pairs/{setting}/{chunk}.log",
    wildcard_constraints:
        chunk="[0-9]{4}",
    conda:
        "../envs/becos.yaml"
    resources:
        mem_mb=RESOURCES.mem_mb("pairs"),
        runtime=RESOURCES.runtime("pairs", n_pairs=chunk_pairs),
    params:
        options=lambda w: bw.job_options(config, "pairs", w.setting),
    shell:
        "becos pairs --options {params.options:q} --setting {wildcards.setting} --chunk {wildcards.chunk}"
        " --ground-truth {input.ground_truth:q} --out {output:q} > {log:q} 2>&1"
