"""Floods on the mesh: ANUGA run in a child process of its own environment (``model``,
``anuga_worker``), two floods compared as a modeller reads them (``compare``), and a report's
summary line (``summary``)."""
