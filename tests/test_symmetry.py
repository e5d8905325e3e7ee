"""viewdb.catalogue.skimming and .symmetry: exact view relations, classification of real renders, no-loss proof.

Render-based tests use silhouette-only renders at 128 px (gap 30: 144 views per model,
plus two models on the full gap-10 grid); a model's curves are rendered once per module.
"""

from __future__ import annotations

import json

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from tests.conftest import sample
from tests.reference import naive_view_relations
from viewdb.camera import camera_pose, grid_views
from viewdb.catalogue.features import mirror_curve
from viewdb.catalogue.skimming import (
    ViewClasses,
    candidate_poses,
    canonical_generator,
    generator_matrix,
    grid_pose_of,
    plan_without_skimming,
    pose_rotation,
    related_views,
    skim_plan,
)
from viewdb.catalogue.symmetry import (
    DEFAULT_SIGMA,
    SymmetryType,
    classify,
    shape_distance,
    views_needed_for_classification,
)

GAPS = [10, 15, 20, 30, 45, 60, 90]

#: No-loss tolerance: a pruned view's fresh curve must be within sigma of its kept view's
#: curve (reversed when mirrored).  Measured worst case at 128 px: 0.0057 (icosphere).
NO_LOSS_TOL = DEFAULT_SIGMA

# Generator sets of common symmetry groups (b = 0 unless stated).
CAR = [("mirror_azimuth", 0)]
MUG = [("mirror_azimuth", 90), ("mirror_y", 0)]
BOX = [("mirror_azimuth", 0), ("mirror_azimuth", 90), ("mirror_y", 0)]
CUBE = [("mirror_azimuth", 0), ("mirror_azimuth", 45), ("rot_horizontal", 90, 0)]
SQUARE_TABLE = [("mirror_azimuth", 0), ("mirror_azimuth", 45)]
TRIANGLE = [("mirror_azimuth", 0), ("mirror_azimuth", 60)]


def _norm(a: float) -> float:
    return float(a % 360)


def rotation_z(deg: float) -> np.ndarray:
    t = np.radians(deg)
    return np.array([[np.cos(t), -np.sin(t), 0], [np.sin(t), np.cos(t), 0], [0, 0, 1.0]])


# ---------------------------------------------------------------------------------------
# Pure geometry
# ---------------------------------------------------------------------------------------


@settings(max_examples=200, deadline=None)
@given(st.sampled_from(GAPS), st.data())
def test_grid_pose_round_trips_and_matches_the_camera_contract(gap, data):
    n = 360 // gap
    h = data.draw(st.integers(0, n - 1)) * gap
    v = data.draw(st.integers(0, n - 1)) * gap
    rot = pose_rotation(h, v)
    np.testing.assert_allclose(rot, camera_pose(h, v)[:3, :3], atol=1e-12)
    assert grid_pose_of(rot, gap) == (h, v)


@settings(max_examples=100, deadline=None)
@given(st.sampled_from([10, 30, 45]), st.data())
def test_off_grid_rolled_and_reflected_cameras_are_not_grid_poses(gap, data):
    n = 360 // gap
    h = data.draw(st.integers(0, n - 1)) * gap
    v = data.draw(st.integers(0, n - 1)) * gap
    assert grid_pose_of(pose_rotation(h + gap / 2, v), gap) is None
    assert grid_pose_of(pose_rotation(h, v + gap / 3), gap) is None
    roll = data.draw(st.floats(1.0, 179.0))
    rolled = grid_pose_of(pose_rotation(h, v) @ rotation_z(roll), gap)
    if v % 180 != 90:
        assert rolled is None
    else:  # at a pole a roll is a change of azimuth: a grid pose iff the roll is on the grid
        on_grid = abs(roll / gap - round(roll / gap)) < 1e-9
        assert (rolled is not None) == on_grid
    assert grid_pose_of(-pose_rotation(h, v), gap) is None  # det -1
    # a roll of exactly 180 degrees is the documented "turned" grid view (h + 180, 180 - v)
    assert grid_pose_of(pose_rotation(h, v) @ rotation_z(180), gap) == (_norm(h + 180), _norm(180 - v))


@pytest.mark.parametrize("gap", [10, 30, 45])
def test_mirror_image_pairing_holds_for_every_object(gap):
    vc = related_views([], gap)
    assert vc.views_stored * 2 == vc.views_grid
    for h, v in grid_views(gap):
        assert vc.relation((h, v), (_norm(h + 180), _norm(-v))) == "mirror"
        assert len(vc.members(h, v)) == 2
        # the turned view (same direction, image upside down) is NOT the same curve
        assert vc.relation((h, v), (_norm(h + 180), _norm(180 - v))) is None
    assert candidate_poses(vc, 90, 90) == [(90.0, 90.0, False), (270.0, 270.0, True)]


@pytest.mark.parametrize("gap", [10, 30])
def test_mirror_plane_x0_gives_the_car_rules(gap):
    np.testing.assert_allclose(generator_matrix(("mirror_azimuth", 0)), np.diag([-1.0, 1, 1]), atol=1e-12)
    vc = related_views(CAR, gap)
    for h, v in grid_views(gap):
        assert vc.relation((h, v), (_norm(-h), v)) in ("mirror", "both")  # (b+d, v) ~ mirror (b-d, v)
        assert vc.relation((h, v), (_norm(180 - h), _norm(-v))) in ("same", "both")  # ~ (b+180-d, -v)
        expected = {(h, v), (_norm(-h), v), (_norm(h + 180), _norm(-v)), (_norm(180 - h), _norm(-v))}
        assert {(a, b) for a, b, _ in vc.members(h, v)} == expected
    # self-mirror exactly on the plane's ring (h = 0 or 180)
    assert vc.is_self_mirror(0, 2 * gap) and vc.is_self_mirror(180, 0) and not vc.is_self_mirror(gap, 0)


def _related(vc: ViewClasses, a, b, kind):
    rel = vc.relation((_norm(a[0]), _norm(a[1])), (_norm(b[0]), _norm(b[1])))
    return rel == "both" or rel == kind


@pytest.mark.parametrize("b", [0, 30, 90])
def test_documented_rules_of_the_types(b):
    gap = 15
    h1v2 = related_views([("rot_y", gap), ("mirror_azimuth", b), ("mirror_y", 0)], gap)
    h2 = related_views([("mirror_azimuth", b)], gap)
    h3 = related_views([("mirror_azimuth", b), ("mirror_azimuth", b + 45)], gap)
    h2v2 = related_views([("mirror_azimuth", b), ("mirror_y", 0)], gap)
    v3 = related_views([("mirror_azimuth", b + 90), ("rot_horizontal", 90, b)], gap)
    for d in range(0, 360, 15):
        for v in range(0, 360, 15):
            assert _related(h2, (b + d, v), (b - d, v), "mirror")
            assert _related(h2, (b + d, v), (b + 180 - d, -v), "same")
            assert _related(h3, (b + d, v), (b + d + 90, v), "same")  # (h, v) == (h + 2P, v)
            assert _related(h3, (b + 45 + d, v), (b + 45 - d, v), "mirror")
            for sign in (1, -1):  # H1/V2: one class per folded elevation
                assert _related(h1v2, (b + d, v), (d, sign * v), "same")
                assert _related(h1v2, (b + d, v), (d, 180 + sign * v), "same")
            assert _related(h2v2, (b + d, v), (b - d, 180 - v), "mirror")
            assert _related(h2v2, (b + d, v), (b + 180 - d, v + 180), "same")
            assert _related(h2v2, (d, v), (d, 180 - v), "same")  # mirror_y
            assert _related(v3, (d, v), (2 * b - d, v + 180), "same")  # half turn about a_b
        assert _related(v3, (b, d), (b, d + 90), "same")  # quarter turn on the ring
    assert h1v2.views_stored == 7  # folded elevations 0, 15, ..., 90
    assert related_views([("rot_y", 10), ("mirror_azimuth", b)], 10).views_stored == 19  # v up to -v


@pytest.mark.parametrize(
    "gens,gap",
    [
        ([], 30),
        (CAR, 30),
        (CAR, 10),
        (MUG, 30),
        (BOX, 10),
        (CUBE, 30),
        (CUBE, 10),
        ([("rot_y", 30), ("mirror_azimuth", 0), ("mirror_y", 0)], 10),
        ([("rot_y", 10), ("mirror_azimuth", 0), ("rot_horizontal", 10, 0)], 10),
        (TRIANGLE, 30),
    ],
)
def test_classes_partition_the_grid_and_map_to_kept_views_of_their_own_class(gens, gap):
    vc = related_views(gens, gap)
    classes = vc.classes()
    flat = [view for cls in classes for view in cls]
    assert sorted(flat) == sorted(grid_views(gap)) and len(flat) == len(set(flat)) == vc.views_grid
    assert len(classes) == vc.views_stored == len(vc.kept) == len(set(vc.kept))
    assert list(vc.kept) == sorted(vc.kept)
    kept_by_class = {vc.class_id(*k): k for k in vc.kept}
    assert len(kept_by_class) == len(vc.kept)
    for view, (kept, mirrored) in vc.mapping.items():
        assert kept == kept_by_class[vc.class_id(*view)]
        rel = vc.relation(view, kept)
        assert rel is not None
        assert mirrored == (rel == "mirror")
        if view == kept:
            assert not mirrored
    for cls in classes:
        kept = [v for v in cls if v in kept_by_class.values()]
        assert len(kept) == 1


def _oracle_relation(oracle, a, b):
    ra, pa, sa = oracle[a]
    rb, pb, _ = oracle[b]
    if ra != rb:
        return None
    if sa:
        return "both"
    return "same" if pa == pb else "mirror"


def _assert_agrees_with_oracle(gens, gap):
    vc = related_views(gens, gap)
    oracle = naive_view_relations([generator_matrix(g) for g in gens], gap)
    views = [(float(h), float(v)) for h, v in grid_views(gap)]
    for a in views:
        for b in views:
            assert vc.relation(a, b) == _oracle_relation(oracle, a, b), (gens, gap, a, b)


@pytest.mark.parametrize(
    "gens,gap",
    [
        (CAR, 30),
        (MUG, 20),
        (BOX, 30),
        (CUBE, 30),
        (CUBE, 45),
        (SQUARE_TABLE, 30),
        (TRIANGLE, 30),
        ([("rot_y", 30), ("mirror_azimuth", 0), ("mirror_y", 0)], 30),
        ([("mirror_elevation", 45, 0)], 45),  # an oblique plane through the x axis
        # a cube's 3-fold axis along (1, 1, 1): lands on the grid only at special views
        ([("matrix", 0, 0, 1, 1, 0, 0, 0, 1, 0)], 45),
        # the cube group again, reached only by words longer than four generators
        ([("mirror_azimuth", 45), ("rot_y", 180), ("rot_horizontal", 90, 0)], 45),
    ],
)
def test_union_find_agrees_with_the_brute_force_oracle(gens, gap):
    _assert_agrees_with_oracle(gens, gap)


POOL = [
    ("mirror_azimuth", 0),
    ("mirror_azimuth", 45),
    ("mirror_azimuth", 90),
    ("mirror_y", 0),
    ("rot_y", 90),
    ("rot_y", 180),
    ("rot_horizontal", 90, 0),
    ("rot_horizontal", 180, 90),
    ("mirror_elevation", 45, 90),
]


@settings(max_examples=12, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(st.lists(st.sampled_from(POOL), min_size=1, max_size=3, unique=True), st.sampled_from([45, 90]))
def test_union_find_agrees_with_the_oracle_on_random_groups(gens, gap):
    _assert_agrees_with_oracle(gens, gap)


def test_canonical_generators_and_their_matrices():
    assert canonical_generator(("mirror_elevation", 90, 37)) == ("mirror_y", 0.0)
    assert canonical_generator(("mirror_elevation", 0, 30)) == ("mirror_azimuth", 120.0)
    assert canonical_generator(("mirror_azimuth", 200)) == ("mirror_azimuth", 20.0)
    for gen in [("mirror_elevation", 30, 200), ("rot_horizontal", 90, 270), ("rot_y", -90), ("mirror_azimuth", 315)]:
        np.testing.assert_allclose(generator_matrix(gen), generator_matrix(canonical_generator(gen)), atol=1e-12)
    for gen in POOL:
        m = generator_matrix(gen)
        np.testing.assert_allclose(m @ m.T, np.eye(3), atol=1e-12)
    # rot_horizontal(a, b) turns (b, v) into (b, v + a)
    g = generator_matrix(("rot_horizontal", 30, 60))
    assert grid_pose_of(g @ pose_rotation(60, 10), 10) == (60.0, 40.0)


def test_candidate_poses_contain_the_papers_eq1_azimuths():
    for gens, period in [(CAR, 90), (SQUARE_TABLE, 45)]:
        vc = related_views(gens, 15)
        for k in range(0, 90, 15):
            cands = {(h, v) for h, v, _ in candidate_poses(vc, k, 0)}
            for i in range(1, 180 // period + 1):
                x = period * (i - 1) + k if i % 2 else period * i - k
                assert (_norm(x), 0.0) in cands, (gens, k, x)
    cands = candidate_poses(related_views(CAR, 30), 30, 60)
    assert cands == [(30.0, 60.0, False), (150.0, 300.0, False), (210.0, 300.0, True), (330.0, 60.0, True)]


def test_plan_without_skimming_keeps_every_view():
    plan = plan_without_skimming(30)
    assert plan.views_stored == plan.views_grid == 144
    assert list(plan.kept) == sorted(grid_views(30))
    assert all(plan.mapping[v] == (v, False) for v in plan.kept)


@pytest.mark.parametrize("gap", [10, 20, 30])
def test_views_needed_for_classification(gap):
    views = views_needed_for_classification(gap)
    grid = set(grid_views(gap))
    assert len(views) == len(set(views)) and set(views) <= grid
    pairs = {(_norm(h + 180), _norm(-v)) for h, v in views}
    assert not pairs & set(views)  # never both members of a mirror-image pair
    covered = set(views) | pairs
    assert {(h, 0.0) for h, _ in grid} <= covered  # horizontal ring
    assert {(0.0, v) for _, v in grid} | {(90.0, v) for _, v in grid if 90 % gap == 0} <= covered
    assert len(views) < len(grid) / 2


# ---------------------------------------------------------------------------------------
# Classification on synthetic curves (no rendering)
# ---------------------------------------------------------------------------------------


def _synthetic_object(gens, gap, seed=0, n=64):
    """Curves of a fictitious object with exactly the symmetry of ``gens``: one random
    smooth curve per class (self-mirror classes get a bisymmetric one)."""
    vc = related_views(gens, gap)
    rng = np.random.default_rng(seed)
    t = np.arange(n) / n
    per_class = {}
    for kept in vc.kept:
        coef = rng.normal(0, 0.15, size=(6, 2))
        c = 1 + sum(a * np.cos(2 * np.pi * (k + 1) * t) + b * np.sin(2 * np.pi * (k + 1) * t) for k, (a, b) in enumerate(coef))
        if vc.is_self_mirror(*kept):
            c = (c + mirror_curve(c)) / 2
        per_class[kept] = c / c.mean()
    curves = {}
    for view, (kept, mirrored) in vc.mapping.items():
        curves[view] = mirror_curve(per_class[kept]) if mirrored else per_class[kept]
    return vc, curves


@pytest.mark.parametrize(
    "gens,gap,expected",
    [
        (CAR, 30, ("H2", "V4")),
        (CAR, 10, ("H2", "V4")),
        (MUG, 30, ("H2", "V2")),
        (BOX, 30, ("H2", "V2")),
        (CUBE, 30, ("H3", "V3")),
        (CUBE, 10, ("H3", "V3")),
        (SQUARE_TABLE, 30, ("H3", "V4")),
        ([("rot_y", 30), ("mirror_azimuth", 0), ("mirror_y", 0)], 30, ("H1", "V2")),
        ([("rot_y", 30), ("mirror_azimuth", 0)], 30, ("H1", "V4")),
        ([("mirror_y", 0)], 30, ("H4", "V2")),
        ([], 30, ("H4", "V4")),
    ],
)
def test_classify_recovers_the_exact_group_of_a_synthetic_object(gens, gap, expected):
    truth, curves = _synthetic_object(gens, gap)
    sym = classify(lambda h, v: curves[(h, v)], gap)
    assert (sym.h_type, sym.v_type) == expected
    plan = skim_plan(sym)
    # the same partition as the truth: nothing lost, nothing left unpruned
    assert plan.views_stored == truth.views_stored
    for view in truth.views:
        assert plan.relation(view, plan.mapping[view][0]) == truth.relation(view, plan.mapping[view][0])


def test_verifier_rejects_a_ring_that_only_looks_symmetric():
    """The horizontal ring is identical all round (Algorithm 1 proposes H1), but off the
    ring the views differ: every proposal must be rejected by the verification."""
    gap, n = 30, 64
    t = np.arange(n) / n
    ring_curve = 1 + 0.2 * np.cos(2 * np.pi * 2 * t)  # bisymmetric
    pairs = related_views([], gap)
    rng = np.random.default_rng(1)
    curves = {}
    for view in pairs.kept:
        c = ring_curve if view[1] in (0.0, 180.0) else 1 + 0.1 * rng.normal(size=n)
        curves[view] = c
    for view, (kept, mirrored) in pairs.mapping.items():
        curves[view] = mirror_curve(curves[kept]) if mirrored else curves[kept]
    sym = classify(lambda h, v: curves[(h, v)], gap)
    assert (sym.h_type, sym.v_type) == ("H4", "V4") and sym.generators == ()
    statuses = {(r.generator, r.status) for r in sym.verification}
    assert (("rot_y", 30.0), "rejected") in statuses
    assert skim_plan(sym).views_stored == 72


def test_symmetry_type_serialises_to_json_and_back():
    _, curves = _synthetic_object(BOX, 30)
    sym = classify(lambda h, v: curves[(h, v)], 30)
    data = json.loads(json.dumps(sym.to_dict()))
    again = SymmetryType.from_dict(data)
    assert again == sym
    assert skim_plan(again).kept == skim_plan(sym).kept
    assert all(r.status in {"accepted", "rejected", "redundant", "unverifiable"} for r in sym.verification)


# ---------------------------------------------------------------------------------------
# Real renders
# ---------------------------------------------------------------------------------------

_CURVES: dict[tuple[str, int], dict[tuple[float, float], np.ndarray]] = {}


def all_curves(stem: str, gap: int) -> dict[tuple[float, float], np.ndarray]:
    """Curves of every grid view, each from its own fresh silhouette render at 128 px."""
    key = (stem, gap)
    if key not in _CURVES:
        from viewdb.catalogue.features import distance_curve
        from viewdb.catalogue.mesh import load_mesh
        from viewdb.catalogue.render import get_renderer
        from viewdb.config import RenderConfig

        mesh = load_mesh(sample(stem))
        renderer = get_renderer(RenderConfig(image_size=128))
        _CURVES[key] = {
            (float(h), float(v)): distance_curve(renderer.render(mesh, h, v, shaded=False).mask)
            for h, v in grid_views(gap)
        }
    return _CURVES[key]


def classify_model(stem: str, gap: int) -> tuple[SymmetryType, list[tuple[float, float]]]:
    curves = all_curves(stem, gap)
    asked: list[tuple[float, float]] = []

    def curve_at(h, v):
        asked.append((h, v))
        return curves[(h, v)]

    return classify(curve_at, gap), asked


# (h_type, v_type, h_period, v_period, base_azimuth, views_stored at gap 30)
EXPECTED = {
    "sphere": ("H1", "V1", 0, 0, 0, 1),
    "cylinder": ("H1", "V2", 0, 90, 0, 4),
    "cone": ("H1", "V4", 0, 180, 0, 7),
    "bottle": ("H1", "V4", 0, 180, 0, 7),
    "torus": ("H1", "V2", 0, 90, 0, 4),
    "cube_dice": ("H3", "V3", 45, 45, 0, 6),
    "marked_cube": ("H3", "V3", 45, 45, 0, 6),
    "box_long": ("H2", "V2", 90, 90, 0, 16),
    "pyramid": ("H3", "V4", 45, 180, 0, 14),
    "table": ("H3", "V4", 45, 180, 0, 14),
    "car": ("H2", "V4", 90, 180, 0, 43),
    "chair": ("H2", "V4", 90, 180, 0, 43),
    # the README expects V4 (the open top breaks y = 0 in 3-D), but the silhouette only
    # sees the outer hull, a cylinder with a vertically centred handle: y = 0 holds.
    "mug": ("H2", "V2", 90, 90, 90, 25),
    "l_bracket": ("H4", "V4", 180, 180, 0, 72),
    "arrow": ("H4", "V4", 180, 180, 0, 72),
}


@pytest.mark.parametrize("stem", sorted(EXPECTED))
def test_sample_models_classify_to_their_expected_types(stem):
    sym, asked = classify_model(stem, 30)
    h_type, v_type, hp, vp, b, stored = EXPECTED[stem]
    assert (sym.h_type, sym.v_type) == (h_type, v_type), sym.verification
    assert (sym.h_period, sym.v_period, sym.base_azimuth) == (hp, vp, b)
    assert skim_plan(sym).views_stored == stored
    # classification asked only for the documented views, each once
    assert sorted(asked) == sorted(views_needed_for_classification(30))
    assert len(sym.h_difference) == len(sym.v_difference) == 12


NO_LOSS_MODELS = ["sphere", "cylinder", "cone", "torus", "car", "cube_dice", "box_long", "table", "mug", "l_bracket"]


def _assert_no_loss(stem: str, gap: int) -> ViewClasses:
    curves = all_curves(stem, gap)
    sym, _ = classify_model(stem, gap)
    plan = skim_plan(sym)
    worst = 0.0
    for view, (kept, mirrored) in plan.mapping.items():
        expect = mirror_curve(curves[kept]) if mirrored else curves[kept]
        err = shape_distance(curves[view], expect)
        if plan.is_self_mirror(*view):  # both parities claimed: check the other one too
            err = max(err, shape_distance(curves[view], mirror_curve(curves[kept])))
        worst = max(worst, err)
        assert err <= NO_LOSS_TOL, (stem, gap, view, kept, mirrored, err)
    assert worst <= NO_LOSS_TOL
    return plan


@pytest.mark.parametrize("stem", NO_LOSS_MODELS)
def test_no_loss_every_pruned_view_equals_its_kept_view_gap30(stem):
    plan = _assert_no_loss(stem, 30)
    assert plan.views_stored == EXPECTED[stem][5]


@pytest.mark.parametrize("stem,stored", [("cube_dice", 45), ("car", 343)])
def test_no_loss_on_the_full_gap10_grid(stem, stored):
    sym, asked = classify_model(stem, 10)
    assert len(asked) == len(views_needed_for_classification(10)) == 120
    assert _assert_no_loss(stem, 10).views_stored == stored


def test_dice_on_a_20_degree_grid_keeps_only_the_grid_preserving_symmetries():
    # 45 and 90 degrees are not on a 20-degree grid: the quarter turns cannot be used, the
    # three mirror planes through the axes (and the pairing) can
    sym, _ = classify_model("cube_dice", 20)
    assert (sym.h_type, sym.v_type) == ("H2", "V2")
    assert skim_plan(sym).views_stored == related_views(BOX, 20).views_stored


def test_the_docstring_table_of_class_counts():
    h_gens = {
        "H1": lambda g: [("rot_y", g), ("mirror_azimuth", 0)],
        "H2": lambda g: [("mirror_azimuth", 0)],
        "H3": lambda g: [("mirror_azimuth", 0), ("mirror_azimuth", 45)],
        "H4": lambda g: [],
    }
    v_gens = {
        "V2": lambda g: [("mirror_y", 0)],
        "V2'": lambda g: [("mirror_y", 0), ("mirror_azimuth", 90)],
        "V3": lambda g: [("mirror_azimuth", 90), ("rot_horizontal", 90, 0)],
        "V4": lambda g: [],
    }
    table = {  # (gap 10, gap 30), as in the module docstring
        "H1": {"V2": (10, 4), "V2'": (10, 4), "V3": (1, 1), "V4": (19, 7)},
        "H2": {"V2": (181, 25), "V2'": (100, 16), "V3": (95, 14), "V4": (343, 43)},
        "H3": {"V2": (50, 8), "V2'": (50, 8), "V3": (45, 6), "V4": (95, 14)},
        "H4": {"V2": (342, 42), "V2'": (181, 25), "V3": (176, 23), "V4": (648, 72)},
    }
    for h, row in table.items():
        for v, counts in row.items():
            got = tuple(related_views(h_gens[h](g) + v_gens[v](g), g).views_stored for g in (10, 30))
            assert got == counts, (h, v)
