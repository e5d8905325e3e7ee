"""Overlays (viewdb.recognition.overlay): the posed mesh is drawn where the object is.

The drawn silhouette is checked against the renderers (pyrender, orthographic and
pinhole), the drawn outline against the true silhouette's edge, and a real query's
overlay against the object in its photo.
"""

from __future__ import annotations

from dataclasses import replace

import cv2
import numpy as np
import pytest
import trimesh
from hypothesis import HealthCheck, assume, example, given, settings
from hypothesis import strategies as st

import viewdb
from tests.conftest import TIERED_DB_MODELS
from viewdb.catalogue.coverage import MeshTriangles, overlap, silhouette
from viewdb.catalogue.pinhole import get_pinhole_renderer
from viewdb.catalogue.render import get_renderer
from viewdb.config import OverlayConfig, RenderConfig
from viewdb.errors import QueryError
from viewdb.pose.frames import GL_TO_CV, view_rotation
from viewdb.pose.silhouette import to_mesh_units
from viewdb.recognition.overlay import (
    AXIS_COLOURS,
    OverlayPose,
    display_size,
    draw_overlay,
    overlay_layer,
    poses_from_json,
    project_silhouette,
)

#: Only the outline, one pixel wide.
OUTLINE_ONLY = OverlayConfig(outline_width=1.0, edge_width=0, fill_opacity=0, axis_length=0, labels=False)
#: Only the filled silhouette, opaque.
FILL_ONLY = OverlayConfig(outline_width=0, edge_width=0, fill_opacity=1.0, axis_length=0, labels=False)

names = st.sampled_from(TIERED_DB_MODELS)
angles = st.floats(0, 360, exclude_max=True)


@pytest.fixture(scope="module")
def db(tiered_db):
    with viewdb.open(tiered_db, read_only=True) as vdb:
        yield vdb


def ortho(name: str, h: float, v: float, inplane: float = 0.0, scale: float = 1.0,
          shift: tuple[float, float] = (0.0, 0.0), width: int = 1) -> OverlayPose:
    """The viewdb-frame pose of view (h, v) turned by ``inplane`` on screen, magnified by
    ``scale``, with the model origin ``shift`` pixels from the centre of a photo ``width``
    pixels wide (the pose's contract in viewdb.pose.estimate)."""
    tx, ty = 2.0 * shift[0] / (width * scale), -2.0 * shift[1] / (width * scale)
    return OverlayPose(name, view_rotation(h, v, inplane), np.array([tx, ty, -3.0]), scale=scale)


def edge_distance(mask: np.ndarray) -> np.ndarray:
    """Each pixel's distance to the nearest pixel of the silhouette's edge (its pixels
    with a 4-neighbour outside it)."""
    m = mask.astype(np.uint8)
    edge = m & ~cv2.erode(m, np.array([[0, 1, 0], [1, 1, 1], [0, 1, 0]], np.uint8),
                          borderType=cv2.BORDER_CONSTANT, borderValue=0)
    return cv2.distanceTransform((edge == 0).astype(np.uint8), cv2.DIST_L2, 5)


def assert_same_silhouette(truth: np.ndarray, mine: np.ndarray) -> None:
    """Equal to a GPU's rasterisation to within its precision: the masks differ only on
    the edge (a pixel centre a hair from it lands on either side), and there on few pixels
    (a half-pixel error of convention would flip most of an edge)."""
    assert truth.any()
    wrong = truth ^ mine
    edge = edge_distance(truth) == 0
    assert edge_distance(truth)[wrong].max(initial=0) <= 1.0, "differs away from the edge"
    assert wrong.sum() <= max(4, 0.1 * edge.sum()), f"{wrong.sum()} of {edge.sum()} edge pixels differ"


def drawn(image: np.ndarray) -> np.ndarray:
    """Pixels an overlay on a black photo drew on (half covered or more)."""
    return image.max(axis=2) >= 128


# ------------------------------------------------------------------ silhouettes
@settings(max_examples=20, suppress_health_check=[HealthCheck.function_scoped_fixture])
@given(name=names, h=angles, v=angles)
@example(name="l_bracket", h=245.8984375, v=0.0)  # a straight edge 0.0006 px past pixel centres
def test_silhouette_equals_the_orthographic_render(db, name, h, v):
    size = 128
    truth = get_renderer(RenderConfig(image_size=size)).render(db.mesh(name), h, v).mask
    mine = project_silhouette(ortho(name, h, v), db.mesh(name), (size, size))
    assert_same_silhouette(truth, mine)


@settings(max_examples=15, suppress_health_check=[HealthCheck.function_scoped_fixture])
@given(name=names, h=angles, v=angles, turn=st.floats(-180, 180), scale=st.floats(0.4, 0.9),
       dx=st.integers(-20, 20), dy=st.integers(-20, 20))
def test_turned_scaled_and_moved_pose_matches_the_warped_render(db, name, h, v, turn, scale, dx, dy):
    """A photo made by turning the view counter-clockwise on screen, scaling and moving
    it (as the demo photo is made) has the pose the contract describes; its drawn
    silhouette is the photo's to within the warp's own resampling (a pixel of either
    outline: shrinking a render drops or keeps thin parts, a chair's legs, by where the
    samples fall, and a dropped part is then the drawing's alone)."""
    size = 256
    truth = get_renderer(RenderConfig(image_size=size)).render(db.mesh(name), h, v).mask
    m = cv2.getRotationMatrix2D(((size - 1) / 2, (size - 1) / 2), turn, scale)
    m[:, 2] += (dx, dy)
    warped = cv2.warpAffine(truth.astype(np.uint8), m, (size, size), flags=cv2.INTER_NEAREST) > 0
    mine = project_silhouette(ortho(name, h, v, turn, scale, (dx, dy), size), db.mesh(name), (size, size))
    wrong = warped ^ mine
    near_an_outline = np.minimum(edge_distance(warped), edge_distance(mine))
    assert near_an_outline[wrong].max(initial=0) <= 1.5


@settings(max_examples=15, suppress_health_check=[HealthCheck.function_scoped_fixture])
@given(name=names, h=angles, v=angles, turn=angles, depth=st.floats(2.5, 6.0),
       tx=st.floats(-0.3, 0.3), ty=st.floats(-0.3, 0.3))
def test_pinhole_silhouette_equals_the_pinhole_render_in_both_units(db, name, h, v, turn, depth, tx, ty):
    size, k = 128, (150.0, 160.0, 61.0, 66.5)
    mesh = db.mesh(name)
    r, t = GL_TO_CV @ view_rotation(h, v, turn), np.array([tx, ty, depth])
    truth, _ = get_pinhole_renderer().render(mesh, r, t, k, size)
    mine = project_silhouette(OverlayPose(name, r, t, frame="opencv"), mesh, (size, size), k)
    assert_same_silhouette(truth, mine)
    # the same pose in the mesh file's own units draws the same
    info = db.object(name)
    in_mesh = OverlayPose(name, r, to_mesh_units(r, t, info.centre, info.scale), frame="opencv", units="mesh")
    placed = project_silhouette(in_mesh, mesh, (size, size), k, (info.centre, info.scale))
    assert (placed ^ mine).sum() <= 2


@settings(max_examples=20, suppress_health_check=[HealthCheck.function_scoped_fixture])
@given(name=names, h=angles, v=angles, turn=angles, depth=st.floats(1.8, 6.0),
       tx=st.floats(-0.5, 0.5), ty=st.floats(-0.5, 0.5), size=st.sampled_from([48, 80, 131]))
def test_cpu_silhouette_equals_the_pinhole_render(db, name, h, v, turn, depth, tx, ty, size):
    """What a silhouette fit renders hundreds of times: the CPU scan conversion
    (viewdb.catalogue.coverage) gives OpenGL's silhouette, window sizes of a fit included."""
    k = (size * 1.2, size * 1.3, size * 0.47, size * 0.52)
    mesh = db.mesh(name)
    r, t = GL_TO_CV @ view_rotation(h, v, turn), np.array([tx, ty, depth])
    renderer = get_pinhole_renderer()
    truth, _ = renderer.render(mesh, r, t, k, size)
    assert_same_silhouette(truth, renderer.silhouette(mesh, r, t, k, size))


@settings(max_examples=25, suppress_health_check=[HealthCheck.function_scoped_fixture])
@given(name=names, h=angles, v=angles, turn=angles, depth=st.floats(1.8, 6.0),
       tx=st.floats(-0.5, 0.5), ty=st.floats(-0.5, 0.5), size=st.sampled_from([48, 80]),
       seed=st.integers(0, 2**16))
def test_overlap_counts_what_the_silhouette_covers(db, name, h, v, turn, depth, tx, ty, size, seed):
    """The fused count a silhouette fit scores with equals the brute force over the
    silhouette image: the weights summed over covered pixels, the valid covered pixels."""
    rng = np.random.default_rng(seed)
    k = (size * 1.2, size * 1.3, size * 0.47, size * 0.52)
    triangles = get_pinhole_renderer().triangles(db.mesh(name))
    r, t = GL_TO_CV @ view_rotation(h, v, turn), np.array([tx, ty, depth])
    weights = rng.random((size, size))
    valid = rng.random((size, size)) < 0.8
    covered = silhouette(triangles, r, t, k, size)
    total, count = overlap(triangles, r, t, k, weights, valid)
    assert total == pytest.approx(float(weights[covered].sum()), rel=1e-12, abs=1e-12)
    assert count == int((covered & valid).sum())


def test_cpu_silhouette_leaves_out_triangles_behind_the_camera():
    triangles = MeshTriangles(np.array([[-1.0, -1, 2], [1, -1, 2], [0, 1, 2], [-1, -1, -2], [1, -1, -2], [0, 1, -2]]),
                              np.array([[0, 1, 2], [3, 4, 5]]))
    front = silhouette(triangles, np.eye(3), np.zeros(3), (10.0, 10.0, 10.0, 10.0), 21)
    alone = silhouette(MeshTriangles(triangles.vertices[:3], [[0, 1, 2]]), np.eye(3), np.zeros(3),
                       (10.0, 10.0, 10.0, 10.0), 21)
    assert front.sum() > 20 and np.array_equal(front, alone)
    with pytest.raises(ValueError, match="vertex"):
        MeshTriangles(triangles.vertices, [[0, 1, 6]])


def _closed_mesh(kind: str, seed: int) -> trimesh.Trimesh:
    """A closed mesh of ``kind``, squashed and sheared at random: one shell, one with two
    faces back to back (a fin, as decimation leaves), or two shells, the inner one
    inside out."""
    rng = np.random.default_rng(seed)
    shape = {"box": lambda: trimesh.creation.box((1.0, 0.6, 0.4)),
             "sphere": lambda: trimesh.creation.icosphere(subdivisions=2),
             "cylinder": lambda: trimesh.creation.cylinder(0.4, 1.2, sections=24),
             "torus": lambda: trimesh.creation.torus(0.6, 0.2, major_sections=24, minor_sections=12)}
    mesh = shape[kind]()
    mesh.apply_transform(np.block([[np.eye(3) + rng.uniform(-0.4, 0.4, (3, 3)), np.zeros((3, 1))],
                                   [np.zeros((1, 3)), np.ones((1, 1))]]))
    vertices, faces = np.asarray(mesh.vertices), np.asarray(mesh.faces)
    fin = faces[rng.integers(len(faces))]
    extra = {"shell": [], "fin": [fin, fin[::-1]]}
    if seed % 3 == 2:  # a second shell inside, wound the other way
        inner = faces[:, ::-1] + len(vertices)
        vertices = np.vstack([vertices, vertices * 0.5])
        faces = np.vstack([faces, inner])
    more = extra["fin"] if seed % 3 == 1 else extra["shell"]
    return trimesh.Trimesh(vertices, np.vstack([faces, *more]) if more else faces, process=False)


@settings(max_examples=40, deadline=None)
@given(kind=st.sampled_from(["box", "sphere", "cylinder", "torus"]), seed=st.integers(0, 2**16),
       h=angles, v=angles, turn=angles, depth=st.floats(1.6, 5.0), tx=st.floats(-0.4, 0.4),
       ty=st.floats(-0.4, 0.4), size=st.sampled_from([31, 80]))
def test_a_closed_mesh_s_front_faces_cover_its_silhouette(kind, seed, h, v, turn, depth, tx, ty, size):
    """A closed mesh in front of the camera is scan-converted from one winding of its faces
    alone; the silhouette and the overlap count are those of every face, pixel for pixel.
    (A mesh the camera's plane cuts shows back faces where its near side is cut away.)"""
    mesh = _closed_mesh(kind, seed)
    culled = MeshTriangles(mesh.vertices, mesh.faces)
    whole = MeshTriangles(mesh.vertices, mesh.faces)
    whole._front = 0
    assert culled.front == -1
    r, t = GL_TO_CV @ view_rotation(h, v, turn), np.array([tx, ty, depth])
    assume(float((mesh.vertices @ r.T + t)[:, 2].min()) > 0.0)  # squashed and sheared, it may reach past 1.6
    k = (size * 1.1, size * 1.2, size * 0.5, size * 0.45)
    assert np.array_equal(silhouette(culled, r, t, k, size), silhouette(whole, r, t, k, size))
    weights = np.random.default_rng(seed).random((size, size))
    valid = weights < 0.7
    (total, count), (every_total, every_count) = (overlap(culled, r, t, k, weights, valid),
                                                  overlap(whole, r, t, k, weights, valid))
    assert count == every_count and total == pytest.approx(every_total, rel=1e-12)  # summed in another order


@settings(max_examples=40, deadline=None, suppress_health_check=[HealthCheck.function_scoped_fixture])
@given(name=names, h=angles, v=angles, seed=st.integers(0, 2**16), size=st.sampled_from([48, 80]),
       step=st.floats(0.0, 0.6))
def test_a_fit_s_compiled_evaluation_is_the_pose_then_its_iou(db, name, h, v, seed, size, step):
    """What a silhouette fit's pattern search evaluates at every step, made and counted in
    one compiled call, equals the pose made in Python and its IoU counted (and a pose
    behind the camera scores 0 without counting as an evaluation)."""
    from viewdb.catalogue.pinhole import Window
    from viewdb.pose.silhouette import _base, _Objective

    rng = np.random.default_rng(seed)
    k = np.array([[size * 1.3, 0.0, size * 0.55], [0.0, size * 1.2, size * 0.45], [0.0, 0.0, 1.0]])
    query = rng.random((size, size)) < 0.4
    ignore = rng.random((size, size)) < 0.1
    window = Window(rng.uniform(-3, 3), rng.uniform(-3, 3), size * rng.uniform(0.8, 1.2), size)
    objective = _Objective(get_pinhole_renderer().triangles(db.mesh(name)), query, ignore, window, k)
    base = _base(GL_TO_CV @ view_rotation(h, v, 30.0), np.array([0.1, -0.2, rng.uniform(2.0, 4.0)]), k)
    p = rng.normal(0.0, 1.0, 6) * np.array([step, step, step, 5.0, 5.0, step])
    fused = objective.iou_at(p, base)
    assert fused == pytest.approx(objective.iou(*objective.pose(p, base)), abs=1e-9)
    assert objective.evaluations == 2
    behind = p.copy()
    behind[5] = -800.0  # depth × e^−800: not in front of the camera
    assert objective.iou_at(behind, base) == 0.0 and objective.evaluations == 2


def compass_reference(objective, rotation, translation, min_steps, start_steps, max_evaluations):
    """The compass search of a silhouette fit written out in Python, one evaluation at a
    time (:meth:`_Objective.iou_at`): each coordinate a step either way, a step that
    improves taken again, steps halved when none does."""
    from viewdb.pose.silhouette import _base

    base = _base(rotation, translation, objective.k)
    p, best = np.zeros(6), objective.iou_at(np.zeros(6), base)
    steps = np.array([start_steps[0]] * 3 + [start_steps[1]] * 2 + [start_steps[2]])
    floor = np.array([min_steps[0]] * 3 + [min_steps[1]] * 2 + [min_steps[2]])
    while objective.evaluations < max_evaluations:
        improved = False
        for i in range(6):
            if steps[i] < floor[i]:
                continue
            for sign in (1.0, -1.0):
                trial = p.copy()
                trial[i] += sign * steps[i]
                if (value := objective.iou_at(trial, base)) > best + 1e-6:
                    p, best, improved = trial, value, True
                    while objective.evaluations < max_evaluations:
                        trial = p.copy()
                        trial[i] += sign * steps[i]
                        if not (value := objective.iou_at(trial, base)) > best + 1e-6:
                            break
                        p, best = trial, value
                    break
        if not improved:
            steps = steps / 2.0
            if np.all(steps < floor):
                break
    return (*objective.pose(p, base), best, objective.evaluations)


@settings(max_examples=25, deadline=None, suppress_health_check=[HealthCheck.function_scoped_fixture])
@given(name=names, h=angles, v=angles, seed=st.integers(0, 2**16), budget=st.integers(1, 300))
def test_a_fit_s_compiled_search_is_the_compass_search(db, name, h, v, seed, budget):
    """A silhouette fit's refinement, one compiled call without the GIL, takes the steps the
    compass search written out in Python takes: the same pose, IoU and evaluations, and
    refinements spread over threads give the same poses in the same order."""
    from viewdb.catalogue.pinhole import Window
    from viewdb.pose.silhouette import _Objective, _search_all

    rng = np.random.default_rng(seed)
    k = np.array([[70.0, 0.0, 32.0], [0.0, 66.0, 30.0], [0.0, 0.0, 1.0]])
    triangles = get_pinhole_renderer().triangles(db.mesh(name))
    truth = GL_TO_CV @ view_rotation(h, v, 40.0), np.array([0.05, -0.1, 3.0])
    query = silhouette(triangles, *truth, tuple(k[[0, 1, 0, 1], [0, 1, 2, 2]]), 64)
    assume(query.any())
    ignore = rng.random(query.shape) < 0.05
    window = Window.around(query, 48)
    steps = (0.12, 3.0, 0.06), (0.02, 0.75, 0.01)
    starts = [(GL_TO_CV @ view_rotation(h + rng.normal(0, 15), v + rng.normal(0, 15), 40.0),
               truth[1] * rng.uniform(0.9, 1.1, 3)) for _ in range(3)]
    expected = [compass_reference(_Objective(triangles, query, ignore, window, k), r, t, steps[1], steps[0],
                                  budget) for r, t in starts]
    for threads in (1, 2):
        objective = _Objective(triangles, query, ignore, window, k)
        found = _search_all(objective, starts, steps[1], steps[0], budget, threads)
        assert objective.evaluations == sum(e[3] for e in expected)
        for (r, t, iou), (r_ref, t_ref, iou_ref, _) in zip(found, expected, strict=True):
            assert iou == iou_ref
            np.testing.assert_array_equal(r, r_ref)
            np.testing.assert_array_equal(t, t_ref)


@pytest.mark.parametrize("name", ["car", "mug"])
def test_a_fit_is_the_same_on_one_thread_and_on_two(db, name):
    """A silhouette fit aligns its views' outlines and refines its starts on threads: the
    same pose and IoU as on one."""
    from viewdb.config import PoseConfig
    from viewdb.pose.matched import pose_silhouette
    from viewdb.pose.silhouette import QUICK
    from viewdb.recognition.pipeline import segment_photo

    k = (300.0, 300.0, 160.0, 120.0)
    truth = GL_TO_CV @ view_rotation(47.0, 21.0, 15.0), np.array([0.1, -0.05, 4.0])
    mask = silhouette(get_pinhole_renderer().triangles(db.mesh(name)), *truth, k, 320)[:240]
    _, _, query = segment_photo(np.dstack([mask * 200] * 3).astype(np.uint8), mask=mask)
    fits = [pose_silhouette(db._catalogue, name, query, PoseConfig(), k, replace(search, threads=threads), ())
            for search in (QUICK, replace(QUICK, fine_starts=1)) for threads in (1, 2)]
    for one, two in (fits[:2], fits[2:]):
        assert one.iou == two.iou > 0.9
        np.testing.assert_array_equal(one.rotation, two.rotation)
        np.testing.assert_array_equal(one.translation, two.translation)


def test_a_forked_child_fits_on_threads_of_its_own():
    """The fits' thread pool is made once per process: a child forked after the parent
    used it (whose threads it does not have) makes its own instead of waiting forever."""
    import os
    import signal

    from viewdb.pose.silhouette import _map

    assert _map(abs, [-1, -2, -3], 2) == [1, 2, 3]
    pid = os.fork()
    if pid == 0:  # pragma: no cover - the child
        signal.alarm(20)  # a hang ends the child with SIGALRM
        os._exit(0 if _map(abs, [-4, -5], 2) == [4, 5] else 1)
    _, status = os.waitpid(pid, 0)
    assert os.WIFEXITED(status) and os.WEXITSTATUS(status) == 0


def test_an_open_mesh_is_scan_converted_whole():
    """A box without its lid, or with a face run twice the same way, is not closed: its
    back faces may be all there is of it."""
    box = trimesh.creation.box()
    assert MeshTriangles(box.vertices, box.faces).front == -1
    assert MeshTriangles(box.vertices, box.faces[2:]).front == 0
    assert MeshTriangles(box.vertices, np.vstack([box.faces, box.faces[:1]])).front == 0
    bowl = MeshTriangles(box.vertices, box.faces[2:])
    r, t, k = GL_TO_CV @ view_rotation(0, 80, 0), np.array([0.0, 0.0, 3.0]), (40.0, 40.0, 20.0, 20.0)
    inside = MeshTriangles(bowl.vertices, bowl.faces[:, ::-1])  # the other winding: the inside seen
    assert silhouette(bowl, r, t, k, 41).sum() == silhouette(inside, r, t, k, 41).sum() > 100


def decimated_share(db, name: str) -> float:
    """The share of faces :meth:`MeshTriangles.simplified` keeps of the mesh made 16 times
    denser and asked for a quarter of that; asserts its silhouette stays the full mesh's
    up to a thin rim from 12 random directions."""
    vertices, faces = db.mesh(name).geometry.vertices, db.mesh(name).geometry.faces
    for _ in range(2):  # as dense as a scan: 16 times the faces, the same surface
        vertices, faces = trimesh.remesh.subdivide(vertices, faces)
    full = MeshTriangles(vertices, faces)
    small = full.simplified(len(full.faces) // 4)
    assert full.simplified(len(full.faces)) is full
    rng = np.random.default_rng(3)
    ious = []
    for _ in range(12):
        r = GL_TO_CV @ view_rotation(*rng.uniform(0, 360, 3))
        t, k = np.array([0.0, 0.0, 3.0]), (100.0, 100.0, 47.5, 47.5)
        a, b = silhouette(full, r, t, k, 96), silhouette(small, r, t, k, 96)
        ious.append((a & b).sum() / (a | b).sum())
    assert min(ious) >= 0.98
    return len(small.faces) / len(full.faces)


def test_a_decimated_mesh_keeps_the_silhouette(db):
    """The coarse steps of a silhouette fit use a dense mesh decimated to about a quarter
    of its faces, or the mesh itself where decimation would change its silhouette (the
    thin-walled mug): either way the silhouette stays the full mesh's up to a thin rim,
    and the car and the bracket are decimated."""
    shares = {name: decimated_share(db, name) for name in ("car", "mug", "chair", "l_bracket")}
    assert shares["car"] <= 0.3 and shares["l_bracket"] <= 0.3 and shares["mug"] == 1.0


# ------------------------------------------------------------------ drawn outline
@pytest.mark.parametrize("name, h, v", [("car", 37, 22), ("mug", 200, 300), ("chair", 120, 15)])
def test_drawn_outline_lies_on_the_true_silhouette_edge(db, name, h, v):
    """A photo wider than high: the pose's scale is relative to the width, so the
    object looks as in a render as wide as the photo, cropped to its height."""
    height, width = 200, 260
    render = get_renderer(RenderConfig(image_size=width)).render(db.mesh(name), h, v).mask
    top = (width - height) // 2
    truth = render[top:top + height]
    image = draw_overlay(np.zeros((height, width, 3), np.uint8), [ortho(name, h, v)], db.mesh,
                         config=OUTLINE_ONLY)
    lines = drawn(image)
    off = edge_distance(truth)[lines]
    assert np.mean(off <= 1.5) >= 0.99, f"drawn outline up to {off.max():.1f} px off the edge"
    reach = cv2.distanceTransform((~lines).astype(np.uint8), cv2.DIST_L2, 5)
    edge = edge_distance(truth) == 0
    assert np.mean(reach[edge] <= 1.5) >= 0.98, "part of the silhouette's edge is not drawn"


def _photo(db, name, h, v, turn, scale, shift):
    """A query photo: view (h, v) turned, scaled and moved on a grey background, and
    the object's true silhouette in it."""
    view = db.render(name, h, v)
    size = view.mask.shape[0]
    m = cv2.getRotationMatrix2D(((size - 1) / 2, (size - 1) / 2), turn, scale)
    m[:, 2] += shift
    color = cv2.warpAffine(view.color, m, (size, size), flags=cv2.INTER_LINEAR)
    mask = cv2.warpAffine(view.mask.astype(np.uint8), m, (size, size), flags=cv2.INTER_NEAREST) > 0
    photo = np.full((size, size, 3), 200, np.uint8)
    photo[mask] = color[mask]
    return photo, mask


def _fit(image: np.ndarray, truth: np.ndarray, tolerance: float) -> tuple[float, float]:
    """Share of the drawn outline within ``tolerance`` px of the true edge, and share of
    the true edge within ``tolerance`` px of the drawn outline."""
    lines = drawn(image)
    near = float(np.mean(edge_distance(truth)[lines] <= tolerance))
    reach = cv2.distanceTransform((~lines).astype(np.uint8), cv2.DIST_L2, 5)
    covered = float(np.mean(reach[edge_distance(truth) == 0] <= tolerance))
    return near, covered


def test_a_query_overlay_fits_the_object_in_the_photo(db):
    """The demo's photo (the mug off the grid, turned 20°, scaled 0.8, moved): query it,
    draw the top result, and the outline lies on the mug's edge in the photo; the same
    pose turned a further 20° does not (the check can tell)."""
    photo, truth = _photo(db, "mug", 37.0, 22.0, 20.0, 0.8, (12, -8))
    result = db.query(photo, k=1).to_dict()
    assert result["results"][0]["object"] == "mug"
    poses = poses_from_json(result)
    assert len(poses) == 1
    black = np.zeros_like(photo)
    near, covered = _fit(draw_overlay(black, poses, db.mesh, config=OUTLINE_ONLY), truth, 2.5)
    assert near >= 0.9 and covered >= 0.85, (near, covered)
    p = poses[0]
    turned = OverlayPose(p.name, view_rotation(0, 0, 20.0) @ p.rotation,
                         view_rotation(0, 0, 20.0) @ p.translation, p.scale)
    near_t, covered_t = _fit(draw_overlay(black, [turned], db.mesh, config=OUTLINE_ONLY), truth, 2.5)
    assert near_t < 0.8 and covered_t < 0.8, (near_t, covered_t)


# ------------------------------------------------------------------ size, layers, axes
def test_a_shrunk_overlay_draws_what_a_smaller_photo_would(db):
    pose = ortho("car", 37, 22, 30, 0.8, (10, -5), 400)
    big = draw_overlay(np.zeros((300, 400, 3), np.uint8), [pose], db.mesh,
                       config=replace(FILL_ONLY, max_side=200))
    small = draw_overlay(np.zeros((150, 200, 3), np.uint8), [ortho("car", 37, 22, 30, 0.8, (5, -2.5), 200)],
                         db.mesh, config=FILL_ONLY)
    assert big.shape == small.shape == (150, 200, 3)
    assert (drawn(big) ^ drawn(small)).sum() <= 4
    assert display_size((3000, 4000, 3), OverlayConfig(max_side=1000)) == (750, 1000)
    # a pinhole pose: the photo shrunk by half is the camera with half the focal length
    r, t, k = GL_TO_CV @ view_rotation(10, 20, 5), np.array([0.05, 0.0, 4.0]), (300.0, 300.0, 199.5, 149.5)
    half = ((k[0] / 2, k[1] / 2, (k[2] + 0.5) / 2 - 0.5, (k[3] + 0.5) / 2 - 0.5))
    pin = OverlayPose("car", r, t, frame="opencv")
    big = draw_overlay(np.zeros((300, 400, 3), np.uint8), [pin], db.mesh, intrinsics=k,
                       config=replace(FILL_ONLY, max_side=200))
    small = draw_overlay(np.zeros((150, 200, 3), np.uint8), [pin], db.mesh, intrinsics=half, config=FILL_ONLY)
    assert (drawn(big) ^ drawn(small)).sum() <= 4


def test_the_layer_over_the_photo_is_the_overlay(db):
    photo, _ = _photo(db, "car", 40.0, 20.0, 0.0, 0.8, (0, 0))
    poses = [ortho("car", 40, 20, 0, 0.8, (0, 0), photo.shape[1])]
    layer = overlay_layer(photo.shape, poses, db.mesh)
    image = draw_overlay(photo, poses, db.mesh)
    a = layer[:, :, 3:].astype(np.float64) / 255
    composed = layer[:, :, :3] * a + photo * (1 - a)
    assert np.abs(composed - image).max() <= 2
    assert layer[0, 0, 3] == 0 and layer[:, :, 3].max() == 255  # transparent where nothing is drawn
    assert (image != photo).any(axis=2).sum() > 0.2 * photo.shape[0] * photo.shape[1]


@pytest.mark.parametrize("h, right, up", [(0.0, 0, 1), (90.0, 2, 1)])
def test_axes_point_along_the_model_axes(db, h, right, up):
    """From the front (h = 0) model x points right and y up; from +X (h = 90, where
    growing azimuth orbits) model z points left and y up."""
    config = OverlayConfig(outline_width=4, edge_width=0, fill_opacity=0, axis_length=0.9, labels=False)
    size = 200
    image = draw_overlay(np.zeros((size, size, 3), np.uint8), [ortho("mug", h, 0.0)], db.mesh, config=config)
    # the outline is drawn too: look at pixels of each axis colour only
    centre = (size - 1) / 2

    def centroid(colour):
        hit = np.all(np.abs(image.astype(int) - colour) <= 40, axis=2)
        ys, xs = np.nonzero(hit)
        assert len(xs) > 20, f"axis colour {colour} not drawn"
        return xs.mean() - centre, ys.mean() - centre

    x, _ = centroid(AXIS_COLOURS[right])
    sign = 1 if right == 0 else -1  # model x to the right at h=0; model z to the left at h=90
    assert sign * x > 0.2 * size
    _, y = centroid(AXIS_COLOURS[up])
    assert y < -0.2 * size


# ------------------------------------------------------------------ input
def test_bad_poses_and_photos_are_refused(db):
    pin = OverlayPose("car", np.eye(3), np.array([0.0, 0.0, 4.0]), frame="opencv")
    with pytest.raises(QueryError, match="intrinsics"):
        draw_overlay(np.zeros((64, 64, 3), np.uint8), [pin], db.mesh)
    with pytest.raises(QueryError, match="frame"):
        OverlayPose("car", np.eye(3), np.zeros(3), frame="opengl")
    with pytest.raises(QueryError, match="finite"):
        OverlayPose("car", np.full((3, 3), np.nan), np.zeros(3))
    with pytest.raises(QueryError, match="8-bit"):
        draw_overlay(np.zeros((64, 64, 3), np.float32), [], db.mesh)
    # nothing to draw: the photo itself
    photo = np.random.default_rng(0).integers(0, 255, (40, 50, 3), dtype=np.uint8)
    assert np.array_equal(draw_overlay(photo, [], db.mesh), photo)


def test_poses_from_json_reads_posed_results_in_order():
    pose = {"rotation": np.eye(3).tolist(), "translation": [0.1, 0.0, -3.0], "scale": 0.5,
            "frame": "viewdb", "units": "normalised"}
    data = {"results": [{"rank": 1, "object": "a", "score": 0.2, "pose": pose},
                        {"rank": 2, "object": "b", "score": 0.3, "pose": None}],
            "objects": [{"region": {}, "results": [{"rank": 1, "object": "c", "score": 0.1, "pose": pose}]}]}
    poses = poses_from_json(data)
    assert [(p.name, p.rank, p.score, p.scale) for p in poses] == [("a", 1, 0.2, 0.5), ("c", 1, 0.1, 0.5)]
    assert np.allclose(poses[0].translation, [0.1, 0.0, -3.0])


# ---------------------------------------------------------------------- the scan conversion
_corner = st.one_of(st.integers(-4, 28).map(lambda v: v / 2.0),  # on pixel centres and edges
                    st.floats(-3.0, 14.0, allow_nan=False))


@settings(max_examples=150, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(st.integers(1, 12), st.integers(1, 12),
       st.lists(st.tuples(st.tuples(_corner, _corner), st.tuples(_corner, _corner), st.tuples(_corner, _corner),
                          st.tuples(*[st.floats(-2.0, 2.0, allow_nan=False)] * 3)), max_size=10))
def test_the_scan_conversion_equals_a_pixel_by_pixel_one(h, w, triangles):
    from tests.reference import naive_face_ids
    from viewdb.recognition.raster import face_ids

    tri = np.array([t[:3] for t in triangles], dtype=np.float64).reshape(-1, 3, 2)
    planes = np.array([t[3] for t in triangles], dtype=np.float64).reshape(-1, 3)
    faces = np.arange(len(tri), dtype=np.int64)[::-1] * 3  # reported indices, not positions
    assert np.array_equal(face_ids(tri, planes, faces, (h, w)), naive_face_ids(tri, planes, faces, (h, w)))
