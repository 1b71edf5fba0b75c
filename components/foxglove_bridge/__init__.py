"""The live Foxglove bridge: the cell on a Foxglove WebSocket server (README.md)."""
