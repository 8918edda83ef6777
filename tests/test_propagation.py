"""Left/right label propagation through the shape network, on real TOSCA meshes and BeCoS label files.

Common frame: y up; TOSCA four-legged animals and centaurs face +z, so x is the lateral axis and an
animal's own left is +x.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import pytest

from becos.build.propagation import (
    LABEL_NAMES,
    NO_LABEL,
    agreement,
    labels_for_instance,
    labels_for_partial,
    labels_through_remesh,
    nearest_annotated,
    propagate_labels,
    propagator,
)


@pytest.fixture(scope="module")
def prepared(tosca_entries, mesh_cache):
    from becos.sources.datasets import prepare_shape

    cache = {}

    def get(name):
        if name not in cache:
            cache[name] = prepare_shape(tosca_entries[name], mesh_cache)
        return cache[name]

    return get


@pytest.fixture(scope="module")
def remeshed(prepared):
    """Remesh variant 0 (seed 42) of the prepared (common-frame) mesh, as the workflow makes it."""
    from becos.build.remesh import remesh, variant_target_vertices

    cache = {}

    def get(name):
        if name not in cache:
            cache[name] = remesh(prepared(name).mesh, target_vertices=variant_target_vertices(42, "tosca", name, 0))
        return cache[name]

    return get


def test_label_values_mean_left_on_plus_x(annotations, prepared):
    """LABEL_NAMES: 1 = left. Horse0 faces +z (head at the top, +z end), so its left is +x."""
    assert LABEL_NAMES[1] == "left" and LABEL_NAMES[0] == "right" and LABEL_NAMES[NO_LABEL] == "none"
    horse = prepared("horse0").mesh.vertices
    head = horse[:, 1] > np.quantile(horse[:, 1], 0.97)
    assert horse[head, 2].mean() > 0.5  # the head is at +z: the horse faces +z
    for name in ("horse0", "centaur0"):
        v = prepared(name).mesh.vertices
        labels = annotations.chirality_labels("tosca", name)
        assert len(labels) == len(v)
        assert ((labels == 1) == (v[:, 0] > 0)).mean() >= 0.985


def test_nearest_annotated_template_by_hops_then_csv_order(tosca_network, tosca_entries):
    expected = {
        "cat0": ("tosca_horse", 2),
        "dog3": ("tosca_horse", 1),
        "wolf1": ("tosca_horse", 2),
        "horse5": ("tosca_horse", 0),
        "centaur2": ("tosca_centaur", 0),
        "michael4": ("faust", 1),
        "victoria0": ("faust", 1),
    }
    for name, (key, hops) in expected.items():
        source, n = nearest_annotated(tosca_network, tosca_entries[name])
        assert (source.key, n) == (key, hops), name

    @dataclass
    class Puma:  # a DT4D shape; its node is 1 hop from horse0, rhinoDJ7S, bear3EP and deerK5L
        dataset: str = "dt4d_animal"
        name: str = "pumaRW/Walk0023"
        template_key: str = "dt4d_animal_pumaRW"

    source, n = nearest_annotated(tosca_network, Puma())
    assert n == 1 and source.key == "tosca_horse" and source.order == 0  # the tie goes to the first CSV row
    # the DT4D rows name a pose; maps land on the node's template, another pose of the same class
    rows = {a.key: a for a in propagator(tosca_network).annotated_templates()}
    assert rows["dt4d_animal_elephantLN0"].annotated == "elephantLN0/act2053"
    assert rows["dt4d_animal_elephantLN0"].name.startswith("elephantLN0/")


def test_identity_path_gives_the_file_labels(tosca_network, tosca_entries, annotations, remeshed, prepared):
    for name, template in (
        ("horse0", "horse0"),
        ("horse5", "horse0"),
        ("centaur0", "centaur0"),
        ("centaur3", "centaur0"),
    ):
        labels = propagate_labels(tosca_network, tosca_entries[name])
        assert labels.dtype == np.int8
        np.testing.assert_array_equal(labels, annotations.chirality_labels("tosca", template))
    # remeshed horse5 (identity path, other pose): a remeshed vertex whose point on the original surface
    # is dominated by one corner (weight >= 0.6) gets that corner's file label
    r = remeshed("horse5")
    labels = propagate_labels(tosca_network, tosca_entries["horse5"], remesh=r)
    assert len(labels) == r.mesh.n_vertices
    to_original = r.to_original
    dominant = to_original.weights.max(axis=1) >= 0.6
    assert dominant.sum() > 0.3 * len(labels)
    corner = to_original.to_vertex_indices(prepared("horse5").mesh.faces)
    np.testing.assert_array_equal(labels[dominant], annotations.chirality_labels("tosca", "horse0")[corner[dominant]])


@pytest.mark.parametrize("name", ["cat0", "cat5"])
def test_cat_legs_carry_the_side_they_stand_on(tosca_network, tosca_entries, prepared, name):
    """Via dog0 -> horse0 (2 hops): leg vertices on +x are left (1), on -x right (0)."""
    v = prepared(name).mesh.vertices
    labels = propagate_labels(tosca_network, tosca_entries[name])
    assert len(labels) == len(v) and (labels != NO_LABEL).all()
    y = v[:, 1]
    legs = (y < y.min() + 0.25 * np.ptp(y)) & (np.abs(v[:, 0]) > 0.05 * np.ptp(v[:, 0]))
    assert legs.sum() > 5000
    assert ((labels[legs] == 1) == (v[legs, 0] > 0)).mean() >= 0.99
    assert (labels[legs & (v[:, 0] > 0)] == 1).mean() >= 0.99  # left legs: the template's left label


def test_centaur_torso_has_no_counterpart_on_a_four_legged_template(tosca_network, tosca_entries, prepared, remeshed):
    """The table annotates centaurs with centaur0 itself (0 hops, every vertex labelled); forced through
    horse0 instead, the human torso (no horse counterpart) gets -1, the horse body keeps labels."""
    own = propagate_labels(tosca_network, tosca_entries["centaur1"])
    assert (own != NO_LABEL).all()
    via_horse = propagate_labels(tosca_network, tosca_entries["centaur1"], annotated="tosca_horse")
    v = prepared("centaur1").mesh.vertices
    assert (via_horse == NO_LABEL).sum() == 9936  # the edge file's -1 rows (centaur0_bottom -> horse0)
    assert (via_horse[v[:, 1] > 0.2] == NO_LABEL).all()  # torso, arms, head
    assert (via_horse[v[:, 1] < -0.3] != NO_LABEL).all()  # legs
    kept = via_horse != NO_LABEL
    assert (via_horse[kept] == own[kept]).mean() >= 0.95  # horse0 and centaur0 agree on the horse body
    r = remeshed("centaur1")
    via_horse_r = propagate_labels(tosca_network, tosca_entries["centaur1"], remesh=r, annotated="tosca_horse")
    carried = labels_through_remesh(via_horse, r, prepared("centaur1").mesh.faces)
    assert ((via_horse_r == NO_LABEL) == (carried == NO_LABEL)).mean() >= 0.98
    assert 0.2 < (via_horse_r == NO_LABEL).mean() < 0.6  # by area, not by the original's vertex density
    assert (via_horse_r[r.mesh.vertices[:, 1] > 0.2] == NO_LABEL).all()


@pytest.mark.parametrize("name", ["cat0", "horse5", "centaur1", "wolf1"])
def test_remeshed_labels_agree_with_original_carried_through_the_remesh(
    tosca_network, tosca_entries, prepared, remeshed, name
):
    """Must-show: direct propagation to the remesh (A) vs propagation to the original triangulation
    carried through ``to_original`` (B) agree on >= 98 % of the vertices labelled in either."""
    r = remeshed(name)
    a = propagate_labels(tosca_network, tosca_entries[name], remesh=r)
    b = labels_through_remesh(propagate_labels(tosca_network, tosca_entries[name]), r, prepared(name).mesh.faces)
    assert len(a) == len(b) == r.mesh.n_vertices
    score = agreement(a, b)
    print(f"\n{name}: agreement {score:.4f} over {r.mesh.n_vertices} remeshed vertices")
    assert score >= 0.98
    assert (a != NO_LABEL).all() and set(np.unique(a)) == {0, 1}


def test_instance_cache_partial_and_missing_data(tosca_network, tosca_entries, remeshed):
    r = remeshed("wolf1")
    first = labels_for_instance(tosca_network, tosca_entries["wolf1"], r)
    again = labels_for_instance(tosca_network, tosca_entries["wolf1"], r)
    assert again is first and not first.flags.writeable
    np.testing.assert_array_equal(first, propagate_labels(tosca_network, tosca_entries["wolf1"], remesh=r))
    original = labels_for_instance(tosca_network, tosca_entries["wolf1"])
    assert len(original) == 4344 and len(first) == r.mesh.n_vertices
    # TOSCA humans are labelled from FAUST tr_reg_000, absent here: no labels, no exception
    assert labels_for_instance(tosca_network, tosca_entries["michael0"]) is None
    from becos.errors import BecosError

    with pytest.raises(BecosError, match="faust"):
        propagate_labels(tosca_network, tosca_entries["michael0"])

    partial_to_full = np.array([0, 5, 7, len(first) - 1])
    np.testing.assert_array_equal(labels_for_partial(first, partial_to_full), first[partial_to_full])
    with pytest.raises(ValueError):
        labels_for_partial(first, np.array([len(first)]))


def test_agreement_counts_vertices_labelled_in_either():
    a = np.array([0, 1, -1, -1, 1], dtype=np.int8)
    b = np.array([0, 0, -1, 1, 1], dtype=np.int8)
    assert agreement(a, b) == pytest.approx(2 / 4)
    assert np.isnan(agreement(np.array([-1]), np.array([-1])))
