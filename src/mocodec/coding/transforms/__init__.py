"""Transforms of sampled signals: wavelets, blocks and the block DCT, subbands, the trend +
wavelet layout, and the smoothing of seams between coded windows."""
