"""Pydantic models of the JSON bodies, for the OpenAPI schema (``/openapi.json``) only.

Requests are validated by the messages' own ``from_dict`` (:mod:`viewdb.search.plans`,
:mod:`viewdb.http.wire`), the one source of truth for what is accepted; these models
describe the same shapes for readers of the schema (a test checks that real messages
validate against them).
"""

from __future__ import annotations

from pydantic import BaseModel, ConfigDict, Field

from ..search.plans import MAX_BAND, MAX_K

__all__ = [
    "CandidateModel",
    "ErrorModel",
    "PoseEntryModel",
    "PoseModel",
    "PoseReplyModel",
    "PoseRequestModel",
    "RefineRequestModel",
    "ServerReplyModel",
    "ShiftWindowModel",
    "WalkRequestModel",
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
        description="content hash of the object's mesh in the file the distance comes from: "
                    "a server ignores the bounds of objects it holds in another version",
    )
    camera_distance: float | None = Field(
        default=None, gt=1,
        description="the view is a perspective silhouette from this many bounding radii "
                    "(absent: an orthographic view)",
    )
    shift: int | None = Field(
        default=None, ge=0,
        description="the query curve matched started at this sample (a shift search; absent: "
                    "the curve as given)",
    )


class ShiftWindowModel(_Strict):
    """Circular shifts of the query curve: every ``step``-th from centre - half_width to
    centre + half_width (mod the curve's length), or all round (half_width null)."""

    centre: int = Field(default=0, ge=0)
    half_width: int | None = Field(default=None, ge=0)
    step: int = Field(default=1, ge=1)


class _CurveRequest(_Strict):
    curve: list[float] = Field(description="the server's curve_samples numbers (see /info)",
                               min_length=8)
    band: int = Field(ge=0, le=MAX_BAND, description="Sakoe-Chiba band in samples")
    k: int = Field(ge=1, le=MAX_K)
    client: list[CandidateModel] = Field(max_length=MAX_K)


class RefineRequestModel(_CurveRequest):
    """CS1: the query's distance curve and the client's top-k on its sparse tier (an empty
    ``client`` list gives the ``server`` plan: exact k-NN on the full tier)."""

    shifts: ShiftWindowModel | None = Field(
        default=None, description="search the smallest distance over these circular shifts of "
                                  "the curve (absent: the curve as given)")


class WalkRequestModel(_CurveRequest):
    """CS2: as for CS1, plus the client file's grid gap the walk starts from."""

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
        description="fx, fy, cx, cy for a perspective (OpenCV-frame) pose; null: orthographic")
    curves: list[list[float] | None] | None = Field(
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
