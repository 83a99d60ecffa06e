"""Nonlinear truth model of a momentum-biased Earth-pointing spacecraft."""
