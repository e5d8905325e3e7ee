"""Photos of several objects: box and point prompts, every object, their errors, the
answer's ``objects``, and the overlay; through the library, the CLI and its JSON."""

from __future__ import annotations

import json
from dataclasses import replace

import cv2
import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from scipy.ndimage import binary_fill_holes

import viewdb
from viewdb.bench.photos import TABLE, table_photo
from viewdb.config import SegmentationConfig
from viewdb.recognition.image import load_image
from viewdb.recognition.regions import Box, Point, Prompts, _separate, find_regions, parse_box, parse_point
from viewdb_cli.main import main

#: Three sample objects on the table, each seen off the database's 30° grid.
SCENE = (("car", 40, 20), ("mug", 130, 25), ("cube_dice", 200, 35))
PLACES = [(10, 40), (280, 20), (540, 50)]
SIZE = (800, 320)


@pytest.fixture(scope="module")
def scene_db(tmp_path_factory):
    from tests.conftest import sample

    path = tmp_path_factory.mktemp("regions") / "scene.db"
    with viewdb.open(path, gap=30, image_size=256) as db:
        report = db.ingest([sample(n) for n in ("cube_dice", "car", "mug", "l_bracket", "chair", "arrow")])
    assert not report.failed
    return path


@pytest.fixture(scope="module")
def scene(scene_db, tmp_path_factory):
    """The photo (RGB), its file, and each object's true mask."""
    with viewdb.open(scene_db, create=False) as db:
        views = [db.render(name, h, v) for name, h, v in SCENE]
    photo, masks = table_photo(views, SIZE, PLACES)
    path = tmp_path_factory.mktemp("photos") / "table.png"
    cv2.imwrite(str(path), photo[:, :, ::-1])
    return photo, path, masks


def iou(a, truth):
    """IoU with the true silhouette, its holes filled (as a segmentation fills them)."""
    b = binary_fill_holes(truth)
    return np.count_nonzero(a & b) / np.count_nonzero(a | b)


def true_box(mask):
    ys, xs = np.nonzero(mask)
    return [int(xs.min()), int(ys.min()), int(xs.max()) + 1, int(ys.max()) + 1]


@pytest.fixture(scope="module")
def every_answer(scene_db, scene):
    photo, _, _ = scene
    with viewdb.open(scene_db, create=False) as db:
        return db.query(photo, k=2, every=True)


# ---------------------------------------------------------------- every object
def test_every_object_on_a_table_is_found_and_recognised(every_answer, scene):
    _, _, masks = scene
    assert len(every_answer.objects) == 3
    assert every_answer.results == []
    found = {}
    for entry in every_answer.objects:
        # each region is one object: it overlaps one true mask, and closely
        overlaps = [iou(entry.region.mask, m) for m in masks]
        which = int(np.argmax(overlaps))
        assert overlaps[which] > 0.85, overlaps
        found[SCENE[which][0]] = entry.results[0].object
        assert entry.results[0].pose is not None
    assert found == {name: name for name, _, _ in SCENE}
    # the largest first
    areas = [o.region.area for o in every_answer.objects]
    assert areas == sorted(areas, reverse=True)


def test_max_objects_keeps_the_largest(scene_db, scene):
    photo, _, masks = scene
    with viewdb.open(scene_db, create=False) as db:
        two = db.query(photo, k=1, every=True, max_objects=2, pose=False)
    largest = sorted(range(3), key=lambda i: -masks[i].sum())[:2]
    assert len(two.objects) == 2
    assert np.abs(np.array([true_box(masks[i]) for i in largest])
                  - np.array([o.region.box for o in two.objects])).max() <= 3


def test_a_label_map_with_every_queries_every_label(scene_db, scene):
    photo, _, masks = scene
    labels = np.zeros(masks[0].shape, np.uint16)
    for value, mask in zip((7, 3, 12), masks, strict=True):
        labels[mask] = value
    with viewdb.open(scene_db, create=False) as db:
        answer = db.query(photo, k=1, label_map=labels, every=True, pose=False)
    got = {o.region.label: o.results[0].object for o in answer.objects}
    assert got == {7: "car", 3: "mug", 12: "cube_dice"}
    assert answer.segmentation == "label"


# ---------------------------------------------------------------- prompts
def test_each_box_and_point_queries_its_object_in_order(scene_db, scene):
    photo, _, masks = scene
    boxes = [true_box(m) for m in masks]
    # a detector's box: a little loose, in floats
    loose = [(x1 - 4.5, y1 - 3.25, x2 + 5.0, y2 + 4.0) for x1, y1, x2, y2 in boxes]
    loose = [(max(0.0, a), max(0.0, b), min(SIZE[0], c), min(SIZE[1], d)) for a, b, c, d in loose]
    centres = []
    for m in masks:  # a pixel deep inside each object
        d = cv2.distanceTransform(m.astype(np.uint8), cv2.DIST_L2, 5)
        y, x = np.unravel_index(int(np.argmax(d)), d.shape)
        centres.append((float(x), float(y)))
    with viewdb.open(scene_db, create=False) as db:
        answer = db.query(photo, k=1, boxes=[loose[2], loose[0]], points=[centres[1]], pose=False)
    assert [o.results[0].object for o in answer.objects] == ["cube_dice", "car", "mug"]
    assert [o.region.prompt for o in answer.objects] == [Box(*loose[2]), Box(*loose[0]), Point(*centres[1])]
    for entry, truth in zip(answer.objects, (masks[2], masks[0], masks[1]), strict=True):
        assert iou(entry.region.mask, truth) > 0.85


def test_the_objects_share_one_decode_and_answer_as_single_queries(scene_db, scene):
    """Each object of a query of several gets the answer a single query with its mask gets."""
    photo, _, _ = scene
    with viewdb.open(scene_db, create=False) as db:
        several = db.query(photo, k=2, every=True, pose=False)
        for entry in several.objects:
            alone = db.query(photo, k=2, mask=entry.region.mask, pose=False)
            assert [(m.object, m.distance) for m in alone.results] == \
                [(m.object, m.distance) for m in entry.results]


def test_a_box_prompted_object_without_colour_is_re_ranked_from_a_deeper_pool(scene_db, scene):
    """An object cut from a box in a photo without colour (no colour channel) is searched
    deeper (``prompt_pool``): its answer is that of a query with its cut-out as the mask
    and that pool."""
    from viewdb.config import RecognitionConfig
    from viewdb.recognition.options import QueryOptions

    photo, _, masks = scene
    photo = cv2.cvtColor(cv2.cvtColor(photo, cv2.COLOR_RGB2GRAY), cv2.COLOR_GRAY2RGB)
    with viewdb.open(scene_db, create=False) as db:
        boxed = db.query(photo, k=2, boxes=[true_box(masks[1])], pose=False).objects[0]
        cut = boxed.region.mask
        deep = db.query(photo, mask=cut, options=QueryOptions(
            k=2, pose=False, recognition=RecognitionConfig(pool=RecognitionConfig().prompt_pool)))
        shallow = db.query(photo, mask=cut, options=QueryOptions(k=2, pose=False))
    # (the box's cut-out keeps its holes for the fit, the mask query fills them: nearly equal fits)
    assert [m.object for m in boxed.results] == [m.object for m in deep.results]
    assert [m.score for m in boxed.results] == pytest.approx([m.score for m in deep.results], rel=0.01)
    assert shallow.results[0].object == deep.results[0].object == "mug"


@pytest.mark.parametrize("prompted, colour, channel, verify, k, expected", [
    (True, True, True, True, 2, 5), (True, True, False, True, 2, 40), (True, False, False, True, 2, 40),
    (False, True, False, True, 2, 5), (True, False, False, False, 2, 2), (False, False, False, True, 7, 7),
    (True, True, True, False, 50, 50),
])
def test_how_many_objects_the_plan_finds_before_the_re_rankings(prompted, colour, channel, verify, k, expected):
    from viewdb.recognition.options import QueryOptions
    from viewdb.recognition.pipeline import pool_size

    assert pool_size(QueryOptions(k=k, verify=verify), prompted, colour, channel) == expected


def test_overlapping_claims_go_to_the_smaller_object():
    a = np.zeros((20, 20), bool)
    a[2:15, 2:15] = True
    b = np.zeros((20, 20), bool)
    b[10:14, 10:14] = True
    out = _separate([a, b])
    assert np.array_equal(out[1], b) and np.array_equal(out[0], a & ~b)


def _two_red_objects():
    """A dark red slab beside a block whose left quarter is the same red and the rest
    blue, on a grey table; their boxes, and the block's true mask."""
    rng = np.random.default_rng(1)
    yy, xx = np.mgrid[:180, :240]
    photo = np.clip(rng.normal((120, 120, 118), 4, (180, 240, 3)), 0, 255).astype(np.uint8)
    red = np.clip(rng.normal((110, 20, 25), 4, (180, 240, 3)), 0, 255).astype(np.uint8)
    slab = (xx >= 20) & (xx < 114) & (yy >= 20) & (yy < 160)
    block = (xx >= 120) & (xx < 200) & (yy >= 50) & (yy < 130)
    reds = slab | (block & (xx < 140))
    photo[reds] = red[reds]
    photo[block & (xx >= 140)] = (30, 40, 170)
    return load_image(photo), [[16, 16, 116, 164], [118, 46, 204, 134]], block


def test_another_prompted_object_is_not_learnt_as_background():
    """The slab reaches into the crop around the block's box: learnt as background, its
    red takes the block's red quarter with it; painted over, the block is cut whole (by
    colour alone: the cut on texture, which would also find it, is left out here)."""
    image, boxes, block = _two_red_objects()
    colour = SegmentationConfig(box_texture_gap=1.0)
    _, kept = find_regions(image, Prompts.of(boxes=boxes), config=colour)
    _, lost = find_regions(image, Prompts.of(boxes=boxes), config=replace(colour, box_others_unknown=False))
    assert iou(kept.mask, block) > 0.95
    assert iou(lost.mask, block) < 0.8
    alone, = find_regions(image, Prompts.of(boxes=boxes[1:]), config=colour)
    assert iou(alone.mask, block) < 0.8  # a box alone cannot know what lies beside it
    # the colour cut of the block alone stops a quarter short of its box's left side: a
    # box is tight, so it is cut again on texture, which keeps the red quarter
    alone, = find_regions(image, Prompts.of(boxes=boxes[1:]))
    assert iou(alone.mask, block) > 0.95


def test_a_box_inside_another_learns_the_outer_object_as_background():
    """A red disc on a blue book, each prompted: the book's box holds the disc's whole, so
    the book around the disc stays its background (not painted over): the disc is cut
    as without the painting, and well."""
    rng = np.random.default_rng(2)
    yy, xx = np.mgrid[:200, :260]
    photo = np.clip(rng.normal((120, 120, 118), 4, (200, 260, 3)), 0, 255).astype(np.uint8)
    book = (xx >= 30) & (xx < 230) & (yy >= 30) & (yy < 170)
    disc = np.hypot(xx - 130, yy - 100) <= 25
    photo[book] = (40, 60, 150)
    photo[disc] = (170, 30, 30)
    image = load_image(photo)
    boxes = [[28, 28, 232, 172], [104, 74, 157, 127]]  # the disc's box tight around it
    _, inner = find_regions(image, Prompts.of(boxes=boxes))
    _, plain = find_regions(image, Prompts.of(boxes=boxes), config=SegmentationConfig(box_others_unknown=False))
    assert np.array_equal(inner.mask, plain.mask)
    assert iou(inner.mask, disc) > 0.95


def test_which_pixels_of_other_boxes_are_painted_over():
    """The background pixels of the crop inside another prompt's box, except a box that
    holds this one whole, and none when they would leave under a tenth of it."""
    from viewdb.recognition.regions import _others_outside

    shape, crop = (100, 100), (10, 10, 60, 60)
    init = np.full((50, 50), cv2.GC_BGD, np.uint8)
    init[10:40, 10:40] = cv2.GC_PR_FGD  # this box: pixels 20..50 of the photo
    box = (20, 20, 50, 50)  # this box's pixels
    beside = _others_outside([Box(45, 0, 100, 30)], box, shape, crop, init)
    expected = np.zeros((50, 50), np.uint8)
    expected[0:20, 35:50] = 1  # photo rows 10..30, columns 45..60, less this box
    expected[init != cv2.GC_BGD] = 0
    assert np.array_equal(beside, expected)
    assert _others_outside([Box(0, 0, 100, 100)], box, shape, crop, init) is None  # holds it
    around = [Box(0, 0, 100, 21), Box(0, 49, 100, 100), Box(0, 0, 21, 100), Box(49, 0, 100, 40)]
    assert _others_outside(around, box, shape, crop, init) is None  # under a tenth left
    assert _others_outside([], box, shape, crop, init) is None


def _printed_white_box():
    """A box on a white table, its grey side and its white printed front: the front's
    white is the table's, only its print tells them apart; its box and true mask."""
    rng = np.random.default_rng(4)
    yy, xx = np.mgrid[:200, :280]
    photo = np.clip(rng.normal(228, 3, (200, 280, 3)), 0, 255).astype(np.uint8)
    side = (xx >= 50) & (xx < 100) & (yy >= 50) & (yy < 150)
    front = (xx >= 100) & (xx < 230) & (yy >= 50) & (yy < 150)
    photo[side] = np.clip(rng.normal(110, 3, (200, 280, 3)), 0, 255).astype(np.uint8)[side]
    for y in range(58, 146, 7):  # lines of print across the front
        x = 106
        while x < 222:
            word = int(rng.integers(4, 14))
            cv2.line(photo, (x, y), (min(x + word, 223), y), (40, 40, 40), 2)
            x += word + int(rng.integers(3, 8))
    return load_image(photo), [48, 48, 232, 152], side | front


def test_a_box_whose_colours_fail_is_cut_on_texture():
    """Colour alone keeps the grey side and loses the white front to the table, far from
    the box's right side; a tight box then cuts again on texture, which keeps the front."""
    from viewdb.recognition.regions import box_gap

    image, box, truth = _printed_white_box()
    by_colour, = find_regions(image, Prompts.of(boxes=[box]), config=SegmentationConfig(box_texture_gap=1.0))
    cut, = find_regions(image, Prompts.of(boxes=[box]))
    assert iou(by_colour.mask, truth) < 0.6 and box_gap(by_colour.mask, tuple(box)) > 0.3
    assert iou(cut.mask, truth) > 0.9


def _busy_photo(seed):
    """A photo of random colour tiles with an object of other random tiles in it: its
    colours are the background's, as a neighbour's are in clutter. The object's mask and
    its tight box."""
    rng = np.random.default_rng(seed)
    h, w = 240, 320

    def tiles():
        return cv2.resize(rng.integers(0, 256, (h // 4, w // 4, 3)).astype(np.uint8), (w, h),
                          interpolation=cv2.INTER_NEAREST)

    photo, truth = tiles(), np.zeros((h, w), np.uint8)
    cv2.ellipse(truth, (160, 120), (30, 45), 0, 0, 360, 1, -1)
    truth = truth.astype(bool)
    photo[truth] = tiles()[truth]
    return load_image(photo), truth, true_box(truth)


@pytest.mark.parametrize("seed", [0, 1, 2, 3])
def test_a_box_in_clutter_is_answered_from_its_middle(seed):
    """GrabCut gives a busy box wholly to the background (no object found); cut again
    with the box's middle surely object, the object is found."""
    image, truth, box = _busy_photo(seed)
    with pytest.raises(viewdb.ImageError, match="no object found"):
        find_regions(image, Prompts.of(boxes=[box]), config=SegmentationConfig(box_core=0.0))
    cut, = find_regions(image, Prompts.of(boxes=[box]))
    assert iou(cut.mask, truth) > 0.65


def test_a_small_object_in_a_large_photo_is_answered_from_its_box():
    """A box's object is small in a 1920 x 1080 photo (0.05 % of it): the box says where
    it is, so its size in the photo does not matter."""
    photo, _ = table_photo([], (1920, 1080), [])
    truth = np.zeros(photo.shape[:2], np.uint8)
    cv2.circle(truth, (900, 500), 14, 1, -1)
    truth = truth.astype(bool)
    photo[truth] = (200, 40, 40)
    cut, = find_regions(load_image(photo), Prompts.of(boxes=[true_box(truth)]))
    assert iou(cut.mask, truth) > 0.8


def test_a_box_past_the_photo_s_edge_is_cut_where_the_photo_ends():
    """An object the frame cuts, its box (a tracker's, say) reaching past the edge: the
    part inside the photo is answered, as from the box cut at the edge."""
    photo, _ = table_photo([], (640, 320), [])
    truth = np.zeros(photo.shape[:2], np.uint8)
    cv2.circle(truth, (8, 160), 40, 1, -1)
    truth = truth.astype(bool)
    photo[truth] = (200, 40, 40)
    x1, y1, x2, y2 = true_box(truth)
    beyond, = find_regions(load_image(photo), Prompts.of(boxes=[[-32, y1, x2, y2]]))
    clipped, = find_regions(load_image(photo), Prompts.of(boxes=[[0, y1, x2, y2]]))
    assert iou(beyond.mask, truth) > 0.8
    assert np.array_equal(beyond.mask, clipped.mask)


def _reference_largest_filled(mask: np.ndarray) -> np.ndarray:
    """The largest 8-connected region with its holes filled, by its definition over the
    whole image (ties to the region first in scan order, as OpenCV labels them)."""
    n, labels = cv2.connectedComponents(mask.astype(np.uint8), connectivity=8)
    if n <= 1:
        return np.zeros(mask.shape, bool)
    sizes = np.bincount(labels.ravel())[1:]
    return binary_fill_holes(labels == 1 + int(np.argmax(sizes)))


@settings(max_examples=60, deadline=None)
@given(st.integers(0, 2**32 - 1), st.integers(0, 6))
def test_the_largest_region_filled_is_its_definition(seed, blobs):
    from viewdb.recognition.segmentation import largest_filled

    rng = np.random.default_rng(seed)
    mask = np.zeros((int(rng.integers(20, 90)), int(rng.integers(20, 90))), np.uint8)
    for _ in range(blobs):
        cv2.ellipse(mask, (int(rng.integers(-10, 100)), int(rng.integers(-10, 100))),
                    (int(rng.integers(1, 25)), int(rng.integers(1, 25))), float(rng.uniform(0, 180)), 0, 360, 1, -1)
        cv2.circle(mask, (int(rng.integers(0, 90)), int(rng.integers(0, 90))), int(rng.integers(1, 6)), 0, -1)
    mask = mask > 0
    np.testing.assert_array_equal(largest_filled(mask), _reference_largest_filled(mask))


def test_a_uniform_box_holds_no_object():
    photo, _ = table_photo([], (640, 320), [])
    with pytest.raises(viewdb.ImageError, match="no object found: the box is uniform"):
        find_regions(load_image(photo), Prompts.of(boxes=[[100, 100, 200, 180]]))


def test_box_gap_is_the_widest_side_gap():
    from viewdb.recognition.regions import box_gap

    mask = np.zeros((50, 60), bool)
    mask[12:40, 10:41] = True
    assert box_gap(mask, (10, 10, 50, 40)) == pytest.approx(max(9 / 40, 2 / 30))
    assert box_gap(mask, (10, 12, 41, 40)) == 0.0


def test_a_box_cut_out_keeps_its_holes_for_the_pose():
    """A ring on a plain background: the region (its curve) is the ring filled, the pose
    is fitted to the ring with the background seen through it; a disc has no pose mask."""
    rng = np.random.default_rng(0)
    photo = np.clip(rng.normal((200, 200, 190), 4, (160, 200, 3)), 0, 255).astype(np.uint8)
    yy, xx = np.mgrid[:160, :200]
    r = np.hypot(xx - 100, yy - 80)
    ring, hole = (r <= 50) & (r >= 25), r < 25
    photo[ring] = (170, 30, 30)
    disc = photo.copy()
    disc[hole] = (170, 30, 30)
    image = load_image(photo)
    region, = find_regions(image, Prompts.of(boxes=[[40, 20, 160, 140]]))
    assert region.pose_mask is not None
    assert not (region.pose_mask & ~region.mask).any()
    assert region.mask[hole].mean() > 0.95  # filled for the curve
    assert region.pose_mask[hole].mean() < 0.05 and region.pose_mask[ring].mean() > 0.95
    solid, = find_regions(load_image(disc), Prompts.of(boxes=[[40, 20, 160, 140]]))
    assert solid.pose_mask is None


@settings(max_examples=40, deadline=None)
@given(st.lists(st.tuples(st.integers(0, 15), st.integers(0, 15), st.integers(1, 8), st.integers(1, 8)),
                min_size=1, max_size=5))
def test_separated_masks_are_disjoint_and_cover_the_union(rects):
    masks = []
    for x, y, w, h in rects:
        m = np.zeros((24, 24), bool)
        m[y:y + h, x:x + w] = True
        masks.append(m)
    out = _separate(masks)
    union = np.logical_or.reduce(masks)
    assert np.array_equal(np.logical_or.reduce(out), union)
    assert (np.sum(out, axis=0) <= 1).all()
    for before, after in zip(masks, out, strict=True):
        assert not (after & ~before).any()
    # the smallest mask keeps every pixel
    smallest = int(np.argmin([m.sum() for m in masks]))
    assert np.array_equal(out[smallest], masks[smallest])


# ---------------------------------------------------------------- errors
@pytest.mark.parametrize("prompts, problem", [
    (Prompts(boxes=(Box(700, 10, 790, 100),)), "outside the 640x320 image"),
    (Prompts(boxes=(Box(-100, 10, -5, 100),)), "outside"),
    (Prompts(boxes=(Box(-100, 10, 2, 100),)), "2x90 pixels inside the image"),
    (Prompts(boxes=(Box(50, 10, 50, 100),)), "degenerate"),
    (Prompts(boxes=(Box(60, 10, 40, 100),)), "degenerate"),
    (Prompts(boxes=(Box(50, 10, 52, 100),)), "degenerate"),
    (Prompts(points=(Point(640, 10),)), "outside"),
    (Prompts(points=(Point(3, -1),)), "outside"),
    (Prompts(boxes=(Box(20, 20, 200, 200),)), "no object found"),
    (Prompts(points=(Point(100, 100),)), "no object found"),
])
def test_bad_prompts_and_empty_photos_raise_one_line_errors(tmp_path, prompts, problem):
    path = tmp_path / "empty table.png"
    photo, _ = table_photo([], (640, 320), [])
    cv2.imwrite(str(path), photo[:, :, ::-1])
    with pytest.raises(viewdb.ImageError) as caught:
        find_regions(load_image(path), prompts)
    message = str(caught.value)
    assert message.startswith(f"{path}: ") and "\n" not in message and problem in message
    if prompts.boxes or prompts.points:
        assert str((prompts.boxes or prompts.points)[0]) in message  # names the prompt


def test_too_many_prompts_are_refused(scene):
    photo, _, _ = scene
    cfg = SegmentationConfig(max_prompts=2)
    with pytest.raises(viewdb.ImageError, match="3 prompts: at most 2"):
        find_regions(load_image(photo), Prompts(points=(Point(1, 1),) * 3), config=cfg)


@pytest.mark.parametrize("text", ["1,2,3", "1,2,3,4,5", "a,b,c,d", "1;2;3;4", "nan,1,2,3", ""])
def test_malformed_boxes_are_refused(text):
    with pytest.raises(viewdb.QueryError, match="box"):
        parse_box(text)


def test_prompts_parse_from_text_and_numbers():
    assert parse_box(" 1.5, 2,3e1 ,40") == Box(1.5, 2.0, 30.0, 40.0) == parse_box((1.5, 2, 30, 40))
    assert parse_point("4,5") == Point(4.0, 5.0) == parse_point([4, 5])
    with pytest.raises(viewdb.QueryError, match="point"):
        parse_point((1, 2, 3))
    with pytest.raises(viewdb.QueryError, match="not both"):
        Prompts.of(boxes=[(1, 2, 30, 40)], every=True)
    with pytest.raises(viewdb.QueryError, match="lists"):
        Prompts.of(boxes="1,2,30,40")
    assert Prompts.of() is None


def test_the_library_refuses_prompts_with_a_mask(scene_db, scene):
    photo, _, masks = scene
    with viewdb.open(scene_db, create=False) as db, pytest.raises(viewdb.QueryError, match="no mask"):
        db.query(photo, mask=masks[0], boxes=[(1, 1, 50, 50)])


# ---------------------------------------------------------------- the CLI
def test_cli_json_lists_each_object(scene_db, scene, capsys):
    _, path, masks = scene
    boxes = [true_box(m) for m in masks]
    args = ["query", str(path), "--db", str(scene_db), "-k", "1", "--no-pose", "--json"]
    assert main([*args, "--box", ",".join(map(str, boxes[1])), "--box", ",".join(map(str, boxes[0]))]) == 0
    data = json.loads(capsys.readouterr().out)
    assert data["results"] == [] and len(data["objects"]) == 2
    assert [o["results"][0]["object"] for o in data["objects"]] == ["mug", "car"]
    first = data["objects"][0]
    assert first["region"]["prompt"] == {"box": [float(v) for v in boxes[1]]}
    assert first["region"]["box"] == pytest.approx(boxes[1], abs=3)
    assert abs(first["region"]["area"] - int(masks[1].sum())) < 0.1 * masks[1].sum()
    # a single-object query keeps its shape: no "objects"
    assert main([*args, "--mask", str(_mask_file(path, masks[0]))]) == 0
    single = json.loads(capsys.readouterr().out)
    assert "objects" not in single and single["results"][0]["object"] == "car"


def _mask_file(photo_path, mask):
    out = photo_path.with_name("car-mask.png")
    cv2.imwrite(str(out), mask.astype(np.uint8) * 255)
    return out


@pytest.mark.parametrize("args, problem", [
    (["--box", "810,10,900,100"], "outside the 800x320 image"),
    (["--box", "50,10,50,100"], "degenerate"),
    (["--box", "5,5,40,30"], "no object found"),
    (["--point", "795,5"], "no object found"),
    (["--point", "900,5"], "outside"),
])
def test_cli_bad_prompts_exit_1_with_one_line(scene_db, scene, capsys, args, problem):
    _, path, _ = scene
    assert main(["query", str(path), "--db", str(scene_db), "--no-pose", *args]) == 1
    err = capsys.readouterr().err.strip()
    assert err.startswith(f"viewdb: {path}: ") and "\n" not in err and problem in err
    assert "Traceback" not in err


def test_every_object_of_an_empty_photo_is_none(scene_db, tmp_path, capsys):
    """Asking for every object of a photo that shows none answers an empty list, in
    Python and from the CLI (exit 0), where one object asked for is a reported error."""
    path = tmp_path / "nothing.png"
    photo, _ = table_photo([], (320, 240), [])
    cv2.imwrite(str(path), photo[:, :, ::-1])
    assert find_regions(load_image(path), Prompts(every=True)) == []
    with viewdb.open(scene_db, create=False) as db:
        answer = db.query(path, every=True).to_dict()
    assert answer["objects"] == [] and answer["results"] == []
    assert main(["query", str(path), "--db", str(scene_db), "--all", "--json"]) == 0
    assert json.loads(capsys.readouterr().out)["objects"] == []
    assert main(["query", str(path), "--db", str(scene_db), "--all"]) == 0
    assert "no object found" in capsys.readouterr().out
    assert main(["query", str(path), "--db", str(scene_db)]) == 1
    err = capsys.readouterr().err.strip()
    assert err.startswith(f"viewdb: {path}: ") and "no object found" in err


@pytest.mark.parametrize("args", [
    ["--box", "1,2,3"], ["--point", "1"], ["--box", "1,2,30,40", "--all"], ["--max-objects", "2"],
    ["--all", "--label", "3"], ["--overlay", "out.jpg"],
])
def test_cli_malformed_prompts_are_usage_errors(scene_db, scene, capsys, args):
    _, path, _ = scene
    assert main(["query", str(path), "--db", str(scene_db), *args]) == 2


# ---------------------------------------------------------------- the overlay
def test_overlay_draws_each_object_over_the_photo(scene_db, scene, every_answer, tmp_path, capsys):
    photo, path, masks = scene
    drawn = every_answer.overlay()
    assert drawn.shape == photo.shape and drawn.dtype == np.uint8
    changed = np.abs(drawn.astype(int) - photo.astype(int)).sum(axis=2) > 30
    near = [cv2.dilate(m.astype(np.uint8), np.ones((41, 41), np.uint8)) > 0 for m in masks]
    # every object is drawn on, and most of what is drawn is on or next to an object
    for m in masks:
        assert (changed & m).sum() > 0.3 * m.sum()
    assert (changed & np.logical_or.reduce(near)).sum() > 0.75 * changed.sum()
    # the CLI writes the same picture
    out = tmp_path / "overlay.png"
    assert main(["query", str(path), "--db", str(scene_db), "-k", "2", "--all", "--overlay", str(out)]) == 0
    written = cv2.imread(str(out))[:, :, ::-1]
    assert np.array_equal(written, drawn)
    assert "object 3" in capsys.readouterr().out


def test_overlay_into_a_missing_folder_fails_before_the_query(scene_db, scene, tmp_path, capsys):
    _, path, _ = scene
    out = tmp_path / "no such folder" / "o.png"
    assert main(["query", str(path), "--db", str(scene_db), "--overlay", str(out)]) == 1
    err = capsys.readouterr().err.strip()
    assert err == f"viewdb: {out}: the folder to write the overlay in does not exist"
    assert not out.parent.exists()


def test_table_photo_is_table_coloured(scene):
    photo, _, masks = scene
    background = ~np.logical_or.reduce(masks)
    assert np.abs(photo[background].mean(axis=0) - TABLE).max() < 15
