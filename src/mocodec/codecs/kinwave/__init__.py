"""kinwave, the project's error-bounded, skeleton-aware wavelet codec (docs/kinwave.md)."""
