"""Motion-aware helpers that more than one codec family uses: the closed loop down the kinematic
tree, rotation-vector forms, VQ codebooks and the model-file framing."""
