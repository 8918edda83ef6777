# Stage 3-4: pair manifests, remeshing per shape (all its variants), ground truth and pair records per chunk.
# A remesh job gets its shape's catalog row as a parameter (not the catalog file), so rewriting the
# catalog never reruns a remesh; a chunk job reruns whenever the manifest is rewritten, but keeps
# every pair file whose input key is unchanged (becos.workflow).


rule manifest:
    input:
        catalog=LAYOUT.catalog,
    output:
        manifest=LAYOUT.manifest("{setting}"),
        remesh_files=LAYOUT.remesh_files("{setting}"),
    log:
        "logs/manifest/{setting}.log",
    # as the catalog: under a second, and the ground-truth jobs wait for it
    priority: 1
    conda:
        "../envs/becos.yaml"
    params:
        options=bw.job_options(config, "manifest"),
        inputs=lambda w: inputs_digest(),  # a rerun trigger only, as for check_datasets
        annotations=config["annotations"],
    shell:
        "becos manifest --options {params.options:q} --annotations {params.annotations:q}"
        " --setting {wildcards.setting} --catalog {input.catalog:q} --out {output.manifest:q}"
        " --remesh-files {output.remesh_files:q} > {log:q} 2>&1"


rule remesh:
    input:
        mesh=lambda w: plan().files[(w.dataset, w.name)],
    output:
        # the shape's folder, written whole: <token>.npz and .ply per variant some pair uses
        directory(LAYOUT.remeshed_folder("{dataset}", "{name}")),
    log:
        "logs/remesh/{dataset}/{name}.log",
    wildcard_constraints:
        dataset="[a-z0-9_]+",
        # any shape name, but not a file in a shape's folder (asked for by name, it is there or not)
        name=r"(?!.*/[vf][0-9]+\.(?:npz|ply)$).+",
    group:
        "remesh"
    conda:
        "../envs/becos.yaml"
    resources:
        mem_mb=RESOURCES.mem_mb("remesh"),
        runtime=RESOURCES.runtime("remesh", n_variants=shape_variants),
    params:
        tokens=lambda w: ",".join(plan().remesh_jobs[(w.dataset, w.name)]),
        # a rerun trigger only (the job derives each target from its token and the seed): a changed token
        # set or target vertex count (becos.build.remesh.variant_target_vertices) reruns the shape
        rerun_key=lambda w: plan().remesh_targets(w.dataset, w.name),
        # and the mesh file's content (becos.workflow.digests): a replaced file reruns it whatever its time
        source=mesh_digest,
        shape=lambda w: plan().shape_json(w.dataset, w.name),
        options=bw.job_options(config, "remesh"),
    shell:
        "becos remesh --options {params.options:q} --shape {params.shape:q} --mesh {input.mesh:q}"
        " --tokens {params.tokens} --out-dir {output:q} > {log:q} 2>&1"


# A chunk job's remesh files are declared by their shapes' folders (input.remeshed, the remesh jobs'
# outputs) and passed one by one in a list file that the manifest job writes (input.remesh_files, every
# chunk's list): a chunk may read hundreds, more than one shell command line holds. Both are named by
# becos.workflow.plan.side_shapes of the chunk's manifest rows, and the job opens only the listed files. Its original meshes (input.meshes) are named by the catalog's
# rows; the annotation folder is passed.
rule ground_truth:
    input:
        manifest=rules.manifest.output.manifest,
        catalog=LAYOUT.catalog,
        remesh_files=rules.manifest.output.remesh_files,
        remeshed=lambda w: plan().chunk_inputs(w.setting, int(w.chunk)),
        meshes=lambda w: plan().chunk_mesh_files(w.setting, int(w.chunk)),
        edges=lambda w: plan().chunk_edge_files(w.setting, int(w.chunk)),
    output:
        LAYOUT.ground_truth_index("{setting}", "{chunk}"),
    log:
        "logs/ground_truth/{setting}/{chunk}.log",
    wildcard_constraints:
        chunk="[0-9]{4}",
    group:
        "chunk"
    conda:
        "../envs/becos.yaml"
    resources:
        mem_mb=RESOURCES.mem_mb("ground_truth"),
        runtime=RESOURCES.runtime("ground_truth", n_pairs=chunk_pairs),
    params:
        options=bw.job_options(config, "ground_truth"),
        sources=chunk_sources_digest,  # a rerun trigger only: the content of what it reads outside results
        annotations=config["annotations"],
    shell:
        "becos ground-truth --options {params.options:q} --annotations {params.annotations:q}"
        " --setting {wildcards.setting} --chunk {wildcards.chunk}"
        " --manifest {input.manifest:q} --catalog {input.catalog:q} --remesh-files {input.remesh_files:q}"
        " --out {output:q} > {log:q} 2>&1"


rule pairs:
    input:
        ground_truth=rules.ground_truth.output[0],
        manifest=rules.manifest.output.manifest,
        catalog=LAYOUT.catalog,
        remesh_files=rules.manifest.output.remesh_files,
        remeshed=lambda w: plan().chunk_inputs(w.setting, int(w.chunk)),
        meshes=lambda w: plan().chunk_mesh_files(w.setting, int(w.chunk)),
        triangle_ids=published_views_input,
    output:
        LAYOUT.pairs_index("{setting}", "{chunk}"),
    log:
        "logs/pairs/{setting}/{chunk}.log",
    wildcard_constraints:
        chunk="[0-9]{4}",
    group:
        "chunk"
    conda:
        "../envs/becos.yaml"
    resources:
        mem_mb=RESOURCES.mem_mb("pairs"),
        runtime=RESOURCES.runtime("pairs", n_pairs=chunk_pairs),
    params:
        options=lambda w: bw.job_options(config, "pairs", w.setting),
        sources=chunk_sources_digest,  # a rerun trigger only, as for ground_truth
        annotations=config["annotations"],
        triangle_ids=lambda w, input: optional_path("--triangle-ids", input.triangle_ids),
    shell:
        "becos pairs --options {params.options:q} --annotations {params.annotations:q}"
        " --setting {wildcards.setting} --chunk {wildcards.chunk}"
        " --ground-truth {input.ground_truth:q} --manifest {input.manifest:q} --catalog {input.catalog:q}"
        " --remesh-files {input.remesh_files:q} {params.triangle_ids} --out {output:q} > {log:q} 2>&1"
