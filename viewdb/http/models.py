"""Pydantic models of the JSON bodies, for the OpenAPI schema (``/openapi.json``) only.

Requests are validated by the messages' own ``from_dict`` (:mod:`viewdb.search.plans`,
:mod:`viewdb.http.wire`), the one source of truth for what is accepted; these models
describe the same shapes for readers of the schema (a test checks that real messages
validate against them).
"""

from __future__ import annotations

import builtins
from typing import Annotated, Any

from pydantic import BaseModel, ConfigDict, Field

from ..catalogue.look import LOOK_DIMS
from ..config import DEFAULT_PLAN, LIMITS
from ..search.plans import MAX_BAND, MAX_CURVES, MAX_K

#: A distance-curve sample: curves have mean 1, so no sample of an n-sample curve exceeds
#: n (the server checks the bound against the curve's own length).
Sample = Annotated[float, Field(ge=0)]

__all__ = [
    "CandidateModel",
    "ErrorModel",
    "ObjectsReplyModel",
    "OverlayRequestModel",
    "PoseEntryModel",
    "PoseModel",
    "PoseReplyModel",
    "PoseRequestModel",
    "RefineRequestModel",
    "ServerReplyModel",
    "ShiftWindowModel",
    "ViewsReplyModel",
    "WalkRequestModel",
    "WebQueryFormModel",
    "WebQueryReplyModel",
    "json_body",
    "multipart_body",
]


class _Strict(BaseModel):
    model_config = ConfigDict(strict=True, extra="ignore", allow_inf_nan=False)


class CandidateModel(_Strict):
    """An object with its best view so far and that view's exact (DTW) distance."""

    object: str = Field(min_length=1)
    distance: float = Field(ge=0)
    azimuth: float
    elevation: float
    mirrored: bool = False
    version: str | None = Field(
        default=None, max_length=128,
        description="the object's version in the file the distance comes from (its mesh's "
                    "content hash and the settings that made its curves): a server ignores "
                    "the bounds of objects it holds in another version",
    )
    camera_distance: float | None = Field(
        default=None, gt=1, le=LIMITS.max_perspective_distance,
        description="the view is a perspective silhouette from this many bounding radii "
                    "(absent: an orthographic view)",
    )
    shift: int | None = Field(
        default=None, ge=0,
        description="the query curve matched started at this sample (a shift search; absent: "
                    "the curve as given)",
    )
    curve_index: int | None = Field(
        default=None, ge=0, lt=MAX_CURVES,
        description="the row of the request's curves that matched (a search of a stack of "
                    "curves; absent: a search of one curve)",
    )


class ShiftWindowModel(_Strict):
    """Circular shifts of the query curve: every ``step``-th from centre - half_width to
    centre + half_width (mod the curve's length), or all round (half_width null)."""

    centre: int = Field(default=0, ge=0)
    half_width: int | None = Field(default=None, ge=0)
    step: int = Field(default=1, ge=1)


class _CurveRequest(_Strict):
    curve: list[Sample] = Field(description="the server's curve_samples numbers (see /info), each "
                                            "in [0, curve_samples] (a curve has mean 1)",
                                min_length=8)
    band: int = Field(ge=0, le=MAX_BAND, description="Sakoe-Chiba band in samples")
    k: int = Field(ge=1, le=MAX_K)
    client: list[CandidateModel] = Field(max_length=MAX_K)


class RefineRequestModel(_CurveRequest):
    """CS1: the query's distance curve (or a stack of curves) and the client's top-k on its
    sparse tier (an empty ``client`` list gives the ``server`` plan: exact k-NN on the full
    tier). CS2: the same with ``shortlist``, the client's shortlist as ``client``. The
    ``fast`` plan: ``fast``, the size of the server's approximate shortlist."""

    curve: list[Sample] | None = Field(  # type: ignore[assignment]
        default=None, min_length=8,
        description="the server's curve_samples numbers (see /info), each in [0, curve_samples] "
                    "(a curve has mean 1); give either curve or curves")
    curves: list[list[Sample]] | None = Field(
        default=None, min_length=1, max_length=MAX_CURVES,
        description="instead of curve: a stack of curves (e.g. the in-plane turns of the "
                    "silhouette), searched in one search for the smallest distance over them; "
                    "each result's curve_index is the row that matched")
    shifts: ShiftWindowModel | None = Field(
        default=None, description="search the smallest distance over these circular shifts of "
                                  "the curve (absent: the curve as given; not with curves)")
    shortlist: bool = Field(
        default=False, description="CS2: search only the objects the client candidates name "
                                   "(the answer is exact among them); absent or false: every object")
    fast: int | None = Field(
        default=None, ge=1, le=100_000,
        description="the fast plan: search only this many objects, those the server's approximate "
                    "index shortlists (the answer is exact among them; every distance a true one); "
                    "absent: every object (not with shortlist)")


class WalkRequestModel(_CurveRequest):
    """CS2 by the paper's walk: as for CS1, plus the client file's grid gap the walk starts from."""

    client_gap: float = Field(gt=0, le=180)


class ServerReplyModel(_Strict):
    results: list[CandidateModel]
    stats: dict[str, float] = Field(description="search counters and server_ms")


class PoseRequestModel(_Strict):
    """The segmented query image and the matches to pose."""

    image: str = Field(description="base64 of an 8-bit RGBA PNG whose alpha is the object mask")
    matches: list[CandidateModel] = Field(min_length=1, max_length=MAX_K)
    intrinsics: list[float] | None = Field(
        default=None, min_length=4, max_length=4,
        description=f"fx, fy, cx, cy in pixels for a perspective (OpenCV-frame) pose (fx, fy in "
                    f"[{LIMITS.min_focal:g}, {LIMITS.max_focal:g}], |cx|, |cy| at most "
                    f"{LIMITS.max_principal:g}); null: orthographic")
    curves: list[list[Sample] | None] | None = Field(
        default=None, description="per match, the query's distance curve at the in-plane turn that "
                                  "matched (its nearest views add pose candidates), or null")
    rerank: bool = Field(default=False, description="with intrinsics: fit every match's perspective "
                                                    "silhouette so they can be ranked by IoU")


class PoseModel(_Strict):
    azimuth: float | None
    elevation: float | None
    inplane: float | None
    scale: float | None
    rotation: list[list[float | None]] = Field(description="3x3 model-to-camera rotation")
    translation: list[float | None]
    method: str = Field(description="sift or shape")
    inliers: int
    candidate: int
    frame: str = Field(description="viewdb or opencv")
    score: float | None


class PoseEntryModel(_Strict):
    pose: PoseModel | None
    error: str | None = Field(description="why there is no pose")


class PoseReplyModel(_Strict):
    poses: list[PoseEntryModel]
    stats: dict[str, float]


class ColourViewModel(_Strict):
    object: str
    azimuth: float
    elevation: float


class ColourRequestModel(_Strict):
    """The stored views whose colour signatures the client needs."""

    views: list[ColourViewModel] = Field(min_length=1, max_length=MAX_K)


class ColourReplyModel(_Strict):
    signatures: list[list[float] | None] = Field(
        description="per view, its rg chromaticity histogram (16 x 16, row by row, sums to 1); "
                    "null when the object's mesh has no colour")
    stats: dict[str, float]


class ColourRankingRequestModel(_Strict):
    """A cut-out's colour signature: which objects' stored colours lie nearest it."""

    signature: list[float] = Field(
        min_length=256, max_length=256,
        description="the cut-out's rg chromaticity histogram (16 x 16, row by row)")
    n: int = Field(ge=1, le=MAX_K, description="how many objects to name")


class ColourMatchModel(_Strict):
    object: str
    distance: float = Field(description="Bhattacharyya distance of its nearest stored view's colours "
                                        "(0 to 1)")
    azimuth: float
    elevation: float


class ColourRankingReplyModel(_Strict):
    matches: list[ColourMatchModel]
    stats: dict[str, float]


class LookRequestModel(_Strict):
    """The look of a cut-out's box: each coloured object's look distance to it."""

    look: list[float] = Field(min_length=LOOK_DIMS, max_length=LOOK_DIMS,
                              description="the box's look (viewdb.catalogue.look.look_features)")


class LookReplyModel(_Strict):
    distances: dict[str, float] = Field(
        description="per coloured object, its look distance (0 the nearest; empty: no look model)")
    stats: dict[str, float]


class FitRequestModel(_Strict):
    """The segmented query image and the stored views to fit to its shape."""

    image: str = Field(description="base64 of an 8-bit RGBA PNG whose alpha is the object mask")
    views: list[ColourViewModel] = Field(min_length=1, max_length=MAX_K)


class FitReplyModel(_Strict):
    fits: list[float | None] = Field(
        description="per view, how well its render fits the query's outline and internal edges "
                    "(0 to 1); null when the view has no silhouette")
    stats: dict[str, float]


class ErrorModel(_Strict):
    """Every error reply."""

    error: str = Field(description="one line saying what was wrong")
    status: int


# ------------------------------------------------------------------ the web page's endpoints
class WebQueryFormModel(BaseModel):
    """``POST /query``: a multipart form."""

    photo: bytes = Field(description="the photo (any format the query accepts: JPEG, PNG, WebP, ...)",
                         json_schema_extra={"format": "binary"})
    plan: str = Field(default=DEFAULT_PLAN, description="fast, server, cs1 or cs2")
    k: int = Field(default=5, ge=1, description="results wanted (at most the server's WebConfig.max_k)")
    pose_top: int | None = Field(default=1, ge=0, description="how many of the best results to pose, "
                                                              "as in the library (the page asks again "
                                                              "for another)")
    box: list[str] = Field(default=[], description="an object's box `x1,y1,x2,y2` in the photo's pixels; "
                                                     "repeat the field for several objects")
    point: list[str] = Field(default=[], description="a pixel `x,y` on an object; repeatable")
    all: bool = Field(default=False, description="every object that stands out from the background")
    max_objects: int | None = Field(default=None, ge=1, description="with `all`: at most this many "
                                                                     "objects, the largest")
    intrinsics: str | None = Field(default=None, description="`fx,fy,cx,cy` in pixels: poses in that "
                                                             "camera's OpenCV frame, in the meshes' units")
    depth: bytes | None = Field(default=None, json_schema_extra={"format": "binary"},
                                description="with `intrinsics`: the photo's depth image, aligned pixel for "
                                            "pixel (16-bit PNG or TIFF, float TIFF, .npy); it sets each "
                                            "pose's distance")
    depth_scale: float = Field(default=0.001, gt=0, description="one depth unit in the meshes' units "
                                                                "(0.001: millimetres against metres)")


class WebViewModel(BaseModel):
    azimuth: float
    elevation: float
    mirrored: bool
    inplane: float
    camera_distance: float | None = None


class WebResultModel(BaseModel):
    """One result of ``viewdb query --json``, plus how to show it."""

    rank: int
    object: str
    distance: float
    view: WebViewModel
    colour_distance: float | None
    shape_fit: float | None
    score: float | None
    # builtins.object: the field ``object`` above shadows the name in this class
    pose: dict[str, builtins.object] | None = Field(description="as in viewdb query --json (null: not posed)")
    pose_error: str | None = None
    overlay: str | None = Field(description="data: URL of a transparent PNG of the posed mesh, as "
                                            "large as `photo`, to lay over it: the best posed result's "
                                            "(the others: POST /overlay; null: not drawn)")
    thumbnail: str = Field(description="URL (relative to the server's root) of the matched view's "
                                       "picture, from the side the photo shows")
    colour: str = Field(description="the colour its overlay is drawn in, #rrggbb")


class WebPhotoModel(BaseModel):
    width: int
    height: int
    source_width: int = Field(description="the photo's own width (POST /overlay takes it)")
    source_height: int
    src: str = Field(description="data: URL of the photo as the server read it (upright, shrunk), JPEG")


class WebObjectResultModel(BaseModel):
    """One object of a photo of several: where it is, and its results."""

    region: dict[str, Any] = Field(description="`box` [x1, y1, x2, y2] (end exclusive), `area` in "
                                               "pixels, and the `prompt` it was cut from")
    segmentation: str
    results: list[WebResultModel]
    timing_ms: dict[str, float]


class WebQueryReplyModel(BaseModel):
    """The ``viewdb query --json`` document, plus pictures to show it."""

    image: str = Field(description="the uploaded file's name")
    plan: str
    k: int
    results: list[WebResultModel]
    timing_ms: dict[str, float] = Field(description="the query's stages, and `overlay`: drawing them")
    segmentation: str
    transfer: dict[str, int]
    photo: WebPhotoModel
    intrinsics: list[float] | None = Field(default=None, description="the form's intrinsics, when given "
                                                                     "(to draw a pinhole pose with)")
    objects: list[WebObjectResultModel] | None = Field(
        default=None, description="a query with prompts or `all`: each object (then `results` is empty)")


class WebObjectModel(BaseModel):
    name: str
    content_hash: str
    faces: int
    vertices: int
    h_type: str | None
    v_type: str | None
    views_stored: int
    views_grid: int
    thumbnail: str = Field(description="URL of a picture of the object")


class ObjectsReplyModel(BaseModel):
    gap: float
    objects: list[WebObjectModel]


class StoredViewModel(BaseModel):
    azimuth: float
    elevation: float
    src: str = Field(description="URL of the view's picture")


class ViewsReplyModel(BaseModel):
    object: str
    gap: float
    views: list[StoredViewModel] = Field(description="by elevation, then azimuth")


class OverlayRequestModel(BaseModel):
    """``POST /overlay``: draw one result's pose."""

    result: dict[str, object] = Field(description="one result of POST /query (its object, rank, score, pose)")
    width: int = Field(ge=16, le=100_000, description="the photo's width in pixels (photo.source_width)")
    height: int = Field(ge=16, le=100_000, description="the photo's height in pixels (photo.source_height)")


def json_body(model: type[BaseModel]) -> dict[str, object]:
    """``openapi_extra`` declaring a JSON request body of ``model`` (documented; the
    endpoint reads and checks the body itself)."""
    return {"requestBody": {"required": True, "content": {"application/json": {
        "schema": {"$ref": f"#/components/schemas/{model.__name__}"}}}}}


def multipart_body(model: type[BaseModel]) -> dict[str, object]:
    """``openapi_extra`` declaring a multipart/form-data request body of ``model``
    (documented; the endpoint reads and checks the form itself)."""
    return {"requestBody": {"required": True, "content": {"multipart/form-data": {
        "schema": {"$ref": f"#/components/schemas/{model.__name__}"}}}}}
