"""The model: normal form, coordinate map U12, their composition, and the NumPyro model."""
