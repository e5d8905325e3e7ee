"""How an :class:`~viewdb.catalogue.appearance.Appearance` is kept in the ``appearances``
table (schema revision 0005): the silhouette and the edge pixels as bit images, the edge
directions and the colour signature as compressed arrays (:mod:`viewdb.storage.codecs`).
Decoding checks what the record promises (shapes, edges inside the silhouette, one
direction per edge pixel), so ``viewdb check`` and a query reject a damaged row alike."""

from __future__ import annotations

from typing import Any

import numpy as np

from ..catalogue.appearance import BINS, Appearance
from ..errors import StorageError
from .codecs import decode_array, decode_bits, encode_array, encode_bits

__all__ = ["appearance_columns", "decode_appearance"]


def appearance_columns(record: Appearance) -> dict[str, Any]:
    """The ``appearances`` columns of a record (without its object)."""
    edges = np.zeros(record.mask.shape, dtype=bool)
    edges[record.edge_points[:, 1], record.edge_points[:, 0]] = True
    return {
        "azimuth": float(record.azimuth), "elevation": float(record.elevation),
        "mask": encode_bits(record.mask), "edges": encode_bits(edges),
        "theta": encode_array(record.edge_theta, compress=True),
        "signature": None if record.signature is None else encode_array(record.signature, compress=True),
    }


def decode_appearance(
    azimuth: float, elevation: float, mask: bytes, edges: bytes, theta: bytes, signature: bytes | None,
    image_size: int,
) -> Appearance:
    """The record of one ``appearances`` row of a file whose views are ``image_size`` square.

    Raises
    ------
    StorageError
        A blob does not decode, or the record breaks its promises.
    """
    shape = (image_size, image_size)
    silhouette = decode_bits(mask, shape)
    edge_bits = decode_bits(edges, shape)
    ys, xs = np.nonzero(edge_bits)  # row-major, the directions' order
    directions = decode_array(theta, np.uint8, (len(xs),))
    if not silhouette[ys, xs].all():
        raise StorageError("appearance: edge pixels outside the silhouette")
    sig = None if signature is None else decode_array(signature, np.uint16, (BINS, BINS))
    return Appearance(float(azimuth), float(elevation), silhouette,
                      np.stack([xs, ys], axis=1).astype(np.int32), directions, sig)
