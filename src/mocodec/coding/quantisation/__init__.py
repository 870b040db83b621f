"""Quantisers: scalar (uniform, mu-law, dead zone), predictive (closed-loop DPCM and its
adaptive forms), vector (LBG), and dead-reckoning extrapolation."""
