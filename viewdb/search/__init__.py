"""k-NN search over the view index (Tak & Hwang, section III.A, Algorithm 2)."""
