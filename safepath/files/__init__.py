"""Files: how safepath reads what users give it and keeps what it derives.

The bottom of the library, above only :mod:`safepath.errors`: reading a user's file
safely (regular files only, size-limited, ``_io``), where the bundled robot and scene
folders are (``_paths``), content digests (``_digest``), and the on-disk cache of what
is computed from a robot alone (:mod:`.derived`). Imports no robot, scene or kernel.
"""
