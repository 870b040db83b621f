"""Perceptually guided wavelet codecs: pwavelet and the embedded spiht."""
