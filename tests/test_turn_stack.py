"""The query's in-plane turns searched as one stack (``RecognitionConfig.turn_search =
"stack"``) give exactly the answer of one search per turn ("separate"): the objects, the
distances, the matched views, orientations and turns, for ``server`` and ``cs1``."""

from __future__ import annotations

import json

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

import viewdb
from tests.reference import naive_knn_over_curves
from tests.test_shifts import random_tier, smooth_curves
from viewdb.bench.photos import composite_photo
from viewdb.config import RecognitionConfig
from viewdb.http import models
from viewdb.recognition.options import QueryOptions
from viewdb.recognition.retrieval import best_of, merge
from viewdb.search.knn import TierArrays
from viewdb.search.plans import MAX_CURVES, Candidate, RefineRequest, neighbours_to_candidates, refine

#: The query's in-plane turns by default.
TURNS = viewdb.QueryOptions().rotations


def _candidates(found, tier: TierArrays, stacked: bool) -> list[Candidate]:
    # the azimuth names the view (row of the tier), so comparing candidates compares views
    return neighbours_to_candidates(found, {v: (float(v), 0.0) for v in range(len(tier.curves))},
                                    stacked=stacked)


def separate(tier, stack, k, band, client=()) -> list[tuple[Candidate, int]]:
    """What the query did before: one search per curve, each bounded by the client's
    candidates and the curves before it (``prior``), merged keeping each object's best."""
    per_curve: list[tuple[float, list[Candidate]]] = []
    for t, curve in enumerate(stack):
        prior = [c for c, _ in merge(per_curve, k)]
        found, _ = refine(tier, RefineRequest(curve, band, k, best_of(list(client), prior, k)))
        per_curve.append((float(t), _candidates(found, tier, False)))
    return [(c, int(t)) for c, t in merge(per_curve, k)]


def stacked(tier, stack, k, band, client=()) -> list[tuple[Candidate, int]]:
    found, _ = refine(tier, RefineRequest.of_stack(stack, band, k, list(client)))
    out = _candidates(found, tier, True)
    return [(Candidate(c.object, c.distance, c.azimuth, c.elevation, c.mirrored), c.curve_index) for c in out]


@settings(max_examples=80, deadline=None)
@given(st.integers(0, 2**32 - 1), st.integers(1, 5), st.integers(0, 6), st.integers(1, 7), st.integers(1, 14),
       st.floats(0.0, 1.0))
def test_one_stack_search_equals_separate_searches_merged(seed, k, band, objects, turns, slack):
    """Random catalogues with repeated and symmetric views and stacks with repeated curves
    (ties everywhere), unbounded and bounded by client candidates (tight or loose): the
    stack reports what the separate searches report, and both are the brute-force answer."""
    rng = np.random.default_rng(seed)
    n = 24
    tier = random_tier(rng, objects, 40, n, int(rng.integers(1, 9)))
    for i in rng.integers(0, 40, 6):  # copies of views within and across objects
        tier.curves[rng.integers(0, 40)] = tier.curves[i]
    tier = TierArrays(tier.names, tier.owner, tier.curves, group_views=tier.group_views)
    stack = smooth_curves(rng, turns, n)
    if rng.random() < 0.5:  # a stored view among the turns, and a repeated turn
        stack[rng.integers(turns)] = tier.curves[rng.integers(40)]
        stack[rng.integers(turns)] = stack[rng.integers(turns)]
    if rng.random() < 0.5:  # two turns each exactly a view of one object: a tie at 0 across turns and views
        views = rng.permutation(np.flatnonzero(tier.owner == tier.owner[rng.integers(40)]))
        for t, view in zip(rng.permutation(turns), views[:2], strict=False):
            stack[t] = tier.curves[view]
    old = separate(tier, stack, k, band)
    new = stacked(tier, stack, k, band)
    assert new == old
    expected = naive_knn_over_curves(list(stack), tier.curves, tier.owner, tier.names, k, band)
    assert [c.object for c, _ in new] == [e[1] for e in expected]
    np.testing.assert_allclose([c.distance for c, _ in new], [e[0] for e in expected], rtol=0, atol=1e-9)
    # a CS1 client's bounds (upper bounds of some objects' distances) change nothing
    everything = stacked(tier, stack, objects, band)
    client = [Candidate(c.object, c.distance * (1 + slack * rng.random()), 0.0, 0.0, False, curve_index=t)
              for c, t in everything if rng.random() < 0.6]
    assert stacked(tier, stack, k, band, client) == new
    assert separate(tier, stack, k, band, [Candidate(c.object, c.distance, 0.0, 0.0, False) for c in client]) == old


def test_a_client_candidate_of_a_curve_outside_the_stack_is_no_bound():
    rng = np.random.default_rng(3)
    tier = random_tier(rng, 4, 30, 16, 4)
    stack = smooth_curves(rng, 3, 16)
    truth = stacked(tier, stack, 2, 3)
    # a lying client: the true best object at distance 0 "by" a curve the stack lacks
    bogus = Candidate(truth[0][0].object, 0.0, 0.0, 0.0, False, curve_index=3)
    assert stacked(tier, stack, 2, 3, [bogus]) == truth


# ----------------------------------------------------------------------------- the wire
def test_stack_requests_round_trip_and_bad_ones_are_refused():
    stack = np.linspace(0.5, 1.5, 128)[None, :] + np.zeros((24, 1))
    client = [viewdb.Candidate("mug", 0.25, 30.0, 60.0, True, curve_index=7)]
    req = RefineRequest.of_stack(stack, 6, 3, client)
    body = json.loads(json.dumps(req.to_dict()))
    assert "curve" not in body and len(body["curves"]) == 24  # an older server refuses it
    models.RefineRequestModel.model_validate(body)
    back = RefineRequest.from_dict(body, 128)
    assert np.array_equal(back.curves, stack) and np.array_equal(back.curve, stack[0]) and back.client == client
    assert RefineRequest.from_dict({**body, "curves": body["curves"][:1]}).stack.shape == (1, 128)
    single = json.loads(json.dumps(RefineRequest(stack[0], 6, 3, []).to_dict()))  # an old client's request
    assert RefineRequest.from_dict(single, 128).curves is None
    bad_bodies = [
        {**body, "curves": body["curves"] * 3 + body["curves"][:1]},  # 73 curves
        {**body, "curves": []},
        {**body, "curve": body["curves"][0]},
        {**body, "shifts": {"centre": 0}},
        {**body, "curves": [body["curves"][0], body["curves"][1][:64]]},
        {**body, "curves": body["curves"][0]},
        {**body, "client": [{**client[0].to_dict(), "curve_index": MAX_CURVES}]},
        {**body, "client": [{**client[0].to_dict(), "curve_index": -1}]},
    ]
    for bad in bad_bodies:
        with pytest.raises(viewdb.QueryError):
            RefineRequest.from_dict(bad, 128)
    with pytest.raises(viewdb.QueryError):
        RefineRequest.of_stack(np.ones((MAX_CURVES + 1, 128)), 6, 3, [])


def test_turn_search_is_checked():
    with pytest.raises(ValueError, match="turn_search"):
        RecognitionConfig(turn_search="both")


# ----------------------------------------------------------------------------- photos
@pytest.fixture(scope="module")
def photo_db(tmp_path_factory):
    from tests.conftest import sample

    folder = tmp_path_factory.mktemp("stack")
    path, client = folder / "q.db", folder / "client.db"
    with viewdb.open(path, gap=30, image_size=192) as db:
        report = db.ingest([sample(n) for n in ("cube_dice", "car", "mug", "l_bracket", "chair", "arrow", "bottle")])
        assert not report.failed
        db.export_client(client, client_gap=90)
    return path, client


@pytest.mark.parametrize("plan", ["server", "cs1"])
def test_photos_get_the_same_answer_from_the_stack_and_from_separate_turns(photo_db, plan):
    path, client_path = photo_db
    with viewdb.open(path, create=False) as db, viewdb.open(client_path, read_only=True) as client:
        kw = {"plan": plan, "pose": plan == "server", "client": client if plan == "cs1" else None}
        cases = [("mug", 14, 50, 15), ("arrow", 300, 200, -70), ("l_bracket", 77, 333, 40), ("car", 200, 15, 130),
                 ("chair", 110, 40, 60), ("bottle", 35, 80, 0), ("cube_dice", 37, 22, 25)]
        for name, h, v, turn in cases:
            img = composite_photo(db.render(name, h, v), turn=turn, scale=0.8, background=200)[0]
            options = {"plan": plan, "pose": kw["pose"]}
            old = db.query(img, client=kw["client"], options=QueryOptions(
                k=3, recognition=RecognitionConfig(turn_search="separate"), **options))
            new = db.query(img, client=kw["client"], options=QueryOptions(k=3, **options))
            assert new.to_dict()["results"] == old.to_dict()["results"], (name, plan)
            if plan == "cs1":  # one round trip instead of one per turn
                assert (new.transfer["round_trips"], old.transfer["round_trips"]) == (1, TURNS)
            # the pool's order by outline alone is the same too, and CS1 still equals server
            outline = {"plan": plan, "pose": False, "colour": False, "verify": False}
            bare = db.query(img, client=kw["client"], options=QueryOptions(k=5, **outline))
            bare_old = db.query(img, client=kw["client"], options=QueryOptions(
                k=5, recognition=RecognitionConfig(turn_search="separate"), **outline))
            assert bare.to_dict()["results"] == bare_old.to_dict()["results"]
            server = db.query(img, options=QueryOptions(k=5, pose=False, colour=False, verify=False))
            assert bare.to_dict()["results"] == server.to_dict()["results"]


def test_an_occluded_labelled_object_searches_its_outline_and_its_completion_in_one_stack(photo_db):
    """A label map whose other label bites into the object: twice the query's turns of curves
    (the silhouette's and its completed outline's), one search, the separate searches' answer."""
    path, client_path = photo_db
    with viewdb.open(path, create=False) as db, viewdb.open(client_path, read_only=True) as client:
        for name, h, v, turn in (("car", 60, 20, 20), ("mug", 200, 35, -45), ("chair", 300, 15, 0)):
            img, mask = composite_photo(db.render(name, h, v), turn=turn, scale=0.8, background=200)
            labels = mask.astype(np.uint8)
            ys, xs = np.nonzero(mask)
            cy, cx = int(ys.mean()), int(xs.max())
            labels[cy - 25:cy + 25, cx - 30:cx + 5] = 2  # an occluder over the right edge
            img[labels == 2] = (40, 90, 160)
            for plan, side in (("server", None), ("cs1", client)):
                runs = [db.query(img, client=side, label_map=labels, label=1, options=QueryOptions(
                    k=3, plan=plan, pose=False, recognition=RecognitionConfig(turn_search=how)))
                    for how in ("separate", "stack")]
                assert runs[1].to_dict()["results"] == runs[0].to_dict()["results"], (name, plan)
                if plan == "cs1":
                    assert (runs[1].transfer["round_trips"], runs[0].transfer["round_trips"]) == (1, 2 * TURNS)
