"""ABB's Externally Guided Motion (EGM) as a gateway link: UDP protobuf, position guidance.
See README.md."""
