"""``python -m twisted.render SRC DST FRICTION WIDTH HEIGHT``: the child that
:func:`twisted.render.gl_top_views` starts with ``MUJOCO_GL`` set; it renders the rope states in SRC
(npz) from above into DST (npz)."""

import sys

from twisted.render.gl import _gl_worker

if __name__ == "__main__":
    _gl_worker(sys.argv[1], sys.argv[2], float(sys.argv[3]), int(sys.argv[4]), int(sys.argv[5]))
