"""Model-based codecs (posture and gesture tables, segment transform coding): posture, gesture,
hybrid, and what they share."""
