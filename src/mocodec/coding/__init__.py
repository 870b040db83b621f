"""Motion-agnostic building blocks the codecs compose, by kind: :mod:`.entropy` (entropy
coders and bit streams), :mod:`.transforms` (wavelets, DCT, subbands) and :mod:`.quantisation`
(scalar, predictive and vector quantisers). None of them knows about skeletons or motions."""
