"""How a recognised object sits: view and camera frames, the orthographic and PnP
solvers, SIFT and outline matching, the perspective silhouette fit, intrinsics."""
