"""The names scripts used before the add-on was split by job (``libfx.render.*``): tests,
benchmarks, farm and artists' scripts call ``libfx.render.on_load_post()`` after
registering the add-on in a file that was already open, read ``libfx.render.RESULTS``
and take ``libfx.render.ctx_lock()`` around the shared context.

Each name is the owning module's own object (the same dict, the same function); nothing
in the add-on imports this module, and new code imports the owners:

    on_load_post              handlers.py     the load_post handler
    RESULTS                   results.py      per (scene name, frame) result records
    ctx_lock                  shared_context  the lock around the shared libfx context
    process_frame, after_render   pipeline.py the frame pipeline
    RESULT_IMAGE              live.py         the "libfx Result" image's name
    log                       log.py          a "libfx: " console line
"""

from .handlers import on_load_post  # noqa: F401
from .live import RESULT_IMAGE  # noqa: F401
from .log import log  # noqa: F401
from .pipeline import after_render, process_frame  # noqa: F401
from .results import RESULTS  # noqa: F401
from .shared_context import lock as ctx_lock  # noqa: F401
