"""Gymnasium environments (``DepthNav-v0``)."""
