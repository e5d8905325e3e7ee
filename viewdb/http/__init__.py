"""The server tier over HTTP: ``viewdb serve`` (:mod:`viewdb.http.app`), the client that
talks to it (:class:`RemoteServer`), and the wire messages of the client–server plans."""

from ..search.plans import Candidate, RefineRequest, ServerReply, WalkRequest
from .client import RemoteServer
from .wire import (
    ColourRankingReply,
    ColourRankingRequest,
    ColourReply,
    ColourRequest,
     FitReply,
    FitRequest,
    LookReply,
    LookRequest,
    PoseReply,
    PoseRequest,
)

__all__ = [
    "Candidate",
    "ColourRankingReply",
    "ColourRankingRequest",
    "ColourReply",
    "ColourRequest",
    "FitReply",
    "FitRequest",
    "LookReply",
    "LookRequest",
    "PoseReply",
    "PoseRequest",
    "RefineRequest",
    "RemoteServer",
    "ServerReply",
    "WalkRequest",
]
