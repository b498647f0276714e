"""Reproducible experiments behind the claims in the README (``lightprobe experiment ...``)."""
