"""Change notices that go up the layers.

A lower module announces a change with ``hooks.notify(name, ...)``; a higher one listens
with ``hooks.listen(name, fn)`` from its register() and stops in its unregister(). So a
property group (props) can say "the stack changed" without importing the live loop, and
the live loop can say "the panels' text changed" without touching editors.

The notices (arguments in brackets):
    stack_changed (scene)        a stack setting changed: parameters, mask, order, quality,
                                 an import (props, recipe, operators); the handlers sync the
                                 passes and the live loop re-runs
    live_changed (scene)         a live setting changed (on/off, while-changing setting, solo,
                                 debug passes): the live loop re-runs
    view_changed (scene)         only what the live image shows changed (before/after, split)
    status_changed ()            what the panels show changed (a live run, a views job)
    result_shown (image)         the "libfx Result" image has new pixels: show it in an editor
    result_replaced (old, new)   the result image was made anew: editors showing old show new

A leaf: nothing of the add-on below it, no bpy. notify calls the listeners in the order they
listened, on the calling thread, and lets their exceptions through (as the direct calls it
replaces did). A name that is not a notice is a KeyError at once, on listen and on notify.
"""

NOTICES = ("stack_changed", "live_changed", "view_changed", "status_changed", "result_shown",
           "result_replaced")

_LISTENERS = {name: [] for name in NOTICES}


def listen(name, fn):
    """fn(*args) is called on every notify(name, *args); listening twice is once."""
    lst = _LISTENERS[name]
    if fn not in lst:
        lst.append(fn)


def unlisten(name, fn):
    lst = _LISTENERS[name]
    if fn in lst:
        lst.remove(fn)


def listeners(name):
    return list(_LISTENERS[name])


def notify(name, *args):
    for fn in list(_LISTENERS[name]):
        fn(*args)


def clear():
    """No listener left (the add-on's unregister, after each module's own)."""
    for lst in _LISTENERS.values():
        lst.clear()
