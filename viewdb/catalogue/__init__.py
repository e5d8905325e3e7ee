"""From a mesh to its views: loading and normalising meshes, rendering, the silhouette
and SIFT features of each view, symmetry classification and skimming, and ingest."""
