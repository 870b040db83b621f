"""Building blocks shared by the codecs: bit I/O (:mod:`bitio`), scalar quantisers
(:mod:`quantizers`, 000 §7.2-7.3), Huffman coding (:mod:`huffman`, §7.4), adaptive range
coding (:mod:`rangecoder`) and zero-run coding (:mod:`rle`). Codecs compose these; none of
them knows about motions."""
