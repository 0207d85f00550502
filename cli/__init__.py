"""The ``ropod-sysid`` command line: a thin click layer over :mod:`ropod_sysid`."""
