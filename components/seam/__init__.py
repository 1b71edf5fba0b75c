"""The seam: a taught path as straight lines and circular arcs (issue 21).

``fit`` splits a path into segments with corners, dwells and outliers; ``seamfile``
reads and writes the seam file (JSON, mm and deg); ``plot`` draws it.  See README.md.
"""
