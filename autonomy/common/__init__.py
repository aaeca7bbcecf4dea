"""What every layer of the robot stack shares: its errors, physical constants, pose
geometry, random streams, atomic file writes and the cache of derived map files."""
