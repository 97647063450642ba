"""Estimation of transformation models from point pairs."""

from .transforms import MODELS, estimate_transform

__all__ = ["MODELS", "estimate_transform"]
