"""Waveform codecs (frame-recursive, transform and vector quantisation coders of the joint
angles): quant, dpcm, adpcm, deadreckoning, dct, subband, svq, tvq."""
