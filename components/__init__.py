"""humanpt: teach a welding robot its path by showing it.

The import package ``humanpt`` is the ``components/`` folder of the repository: one
sub-package per component, plus ``runtime`` (shells, recording, replay, config),
``geometry`` (the PSVS model) and ``cli``.
"""

__version__ = "0.1.0"
