"""Entropy coders and the bit and byte streams they write: adaptive range and binary arithmetic
coding, Huffman, run lengths, SPIHT set partitioning, the context-adaptive coefficient coder, and
length-prefixed parts."""
