"""``twisted browse``: the store in a web browser (Datasette, read-only, on 127.0.0.1), with pictures.

Datasette (the optional extra ``twisted-knots[browse]``) serves the SQLite file: every table and view,
filters, facets, JSON and CSV. This package adds what is ours: the canned queries of the README's
questions (:mod:`twisted.browse.queries`), a plugin that draws ropes, states and knots in the cells
and links runs and states to what they made (:mod:`twisted.browse.plugin`), the pictures as inline SVG
(:mod:`twisted.browse.svg`), and the server (:mod:`twisted.browse.server`). Only :mod:`plugin` and
:mod:`server` import Datasette. See docs/browse.md.
"""
