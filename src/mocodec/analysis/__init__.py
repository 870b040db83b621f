"""Data analysis of motion (000 ch. 5): statistics and usable resolution, temporal
correlation and stationarity, densities, spectra and bit-rate estimates."""

from mocodec.analysis.report import analyze, summary_text

__all__ = ["analyze", "summary_text"]
