"""The steps strung together: the input's kind decided once (``source``), the whole chain
(``pipeline``), the scale series (``series``) and each step as a file-level function
(``files``) that the command line, QGIS's worker and the library call."""
