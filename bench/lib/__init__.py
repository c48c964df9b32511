"""Code shared by the scripts in bench/ (not a benchmark itself): ``steps``, plan steps of stored searches."""
