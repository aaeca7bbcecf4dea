"""The vector map and what is derived from it: loading and hygiene, free space, the
navigation graph (built from walls, checked, planned on) and ray casting against walls."""
