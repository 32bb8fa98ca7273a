"""Floods on the mesh: ANUGA run in a child process of its own environment (``model``,
``anuga_worker``) and two floods compared as a modeller reads them (``compare``)."""
