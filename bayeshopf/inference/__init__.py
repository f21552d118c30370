"""Inference: data-driven start, MAP (optax Adam then L-BFGS), SVI from the MAP point."""
