"""The figures the two theses publish, for drawing beside ours.

000 (Appendix III) gives bit rates and PSNR of its coders on its own 30 Hz sequences of
about 52 DOFs (waveform coders: the conversation sequence, PSNR; model-based coders: the dance
sequence, VPSNR). 001 gives compression ratios vs 32-bit floats (tables 3.1, 5.1, 6.2; its
coders on 56-DOF CMU AMC clips at 120 fps) and times per frame on a 2.66 GHz Core 2 Duo
(tables 3.4, 5.3, 6.4). The clips and machines differ from ours; the report says so.
"""

from __future__ import annotations

APPENDIX_III_FPS = 30.0
APPENDIX_III_DOFS = 52

# codec -> [(knob value, bit/s, dB)], the knob being our codec's quality knob at the thesis's setting
APPENDIX_III: dict[str, list[tuple[float, float, float]]] = {
    "quant": [
        (8, 4454.8, 9.9),
        (16, 6135.6, 16.7),
        (32, 7812.9, 23.0),
        (64, 9476.0, 29.1),
        (128, 11062.1, 35.2),
        (256, 12526.4, 41.3),
    ],
    "dpcm": [
        (4, 2356.5, 13.4),
        (8, 3548.7, 24.1),
        (16, 5285.1, 31.1),
        (32, 7090.6, 38.1),
        (64, 8897.8, 44.7),
        (128, 10594.6, 51.0),
        (256, 12141.0, 57.3),
    ],
    "adpcm": [(4, 2939.8, 10.7), (8, 3325.4, 23.2), (16, 4048.2, 31.4), (32, 5267.9, 38.7), (64, 6784.6, 44.1)],
    "deadreckoning": [
        (1.6, 2567.3, 4.4),
        (0.8, 4049.3, 9.2),
        (0.4, 5967.0, 13.5),
        (0.2, 8344.5, 18.3),
        (0.1, 10884.5, 22.4),
        (0.05, 13048.7, 28.0),
        (0.025, 14996.4, 33.1),
        (0.0125, 16140.5, 35.5),
    ],
    "dct": [(0, 1669.5, 20.0), (1, 2507.8, 24.8), (2, 3295.5, 28.3), (3, 4019.4, 30.5), (4, 4784.7, 31.1)],
    "svq": [
        (16, 747.3, -0.8),
        (32, 959.6, 0.5),
        (64, 1519.1, 1.7),
        (128, 2145.1, 3.2),
        (256, 2569.6, 4.6),
        (512, 2910.3, 6.1),
    ],
    "tvq": [
        (16, 988.4, 7.5),
        (32, 1254.7, 10.0),
        (64, 1586.8, 12.7),
        (128, 1972.5, 15.3),
        (256, 2412.3, 18.4),
        (512, 2906.4, 22.0),
    ],
    "posture": [
        (80.0, 67.7, 3.8),
        (40.0, 101.2, 6.5),
        (26.6667, 317.2, 7.3),
        (20.0, 440.5, 7.5),
        (16.0, 566.8, 7.8),
        (13.3333, 666.5, 8.2),
        (10.0, 762.8, 8.5),
    ],
    "gesture": [(20.0, 145.1, 4.1), (10.0, 165.5, 5.5), (5.0, 214.3, 7.8), (2.0, 293.3, 11.5), (1.0, 310.2, 12.4)],
    "hybrid": [
        (0, 749.7, 10.8),
        (1, 1034.0, 13.7),
        (2, 1194.5, 15.0),
        (3, 1313.0, 15.7),
        (4, 1413.5, 16.2),
        (5, 1497.2, 16.5),
        (6, 1573.2, 16.7),
        (7, 1640.3, 16.9),
    ],
}
APPENDIX_III_MEASURE = {c: ("vpsnr_db" if c in ("posture", "gesture", "hybrid") else "psnr_db") for c in APPENDIX_III}

# 001 table 3.1: pwavelet (QP 9, W 256) user-study scores (1-5) at compression ratios
TABLE_3_1 = {
    "02_02": {20: 4.705, 25: 4.545, 30: 4.159, 35: 3.886, 40: 3.727},
    "49_14": {20: 4.885, 25: 4.615, 30: 4.115, 35: 3.923, 40: 3.404},
}
# 001 table 5.1: primitives at t_L = 0.01, compression ratio per clip (average 48:1)
TABLE_5_1 = {"94_02": 62, "61_04": 51, "79_17": 52, "79_44": 50, "135_04": 40, "138_02": 44, "90_02": 38}
TABLE_5_1_KNOB = 0.01
# 001 tables 5.2 / 6.2: ratios the literature reports (average, best)
TABLE_6_2 = {"Arikan 2006": (30, 30), "Beaudoin et al. 2007": (25, 48), "Gu et al. 2009": (25, 50), "gzip": (3.3, 3.3)}
TABLE_6_2_SPIHT_RATIO = 80
# microseconds per frame (encode, decode): 001 table 3.4 (pwavelet), 5.3 (primitives, range), 6.4 (spiht)
SPEED_US = {
    "pwavelet": ((24.2, 25.5), None),
    "primitives": ((1660, 2370), (110, 140)),
    "spiht": ((520, 520), (100, 100)),
}
