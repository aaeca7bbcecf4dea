"""Visualisation: rerun recordings (the only rerun importer) and map figures."""
