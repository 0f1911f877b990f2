"""The add-on's one worker thread: Blender's UI thread never waits for a read, a stack or
a write.

Two queues: a one-slot queue of jobs (a newer job replaces one still waiting, and cancels a
running final one through ``obsolete``) and a FIFO of tasks that must all run, in order,
before any job (F12's result writes, Apply to Last Render). A job is an object with
``generation``, ``kind`` ("interactive" or "final") and ``run(obsolete)``, which returns
what the main thread shows (put in ``results``) or None. The worker touches no Blender
data; the main thread collects ``results`` from a timer. No bpy.
"""

import threading
import time

from .log import log, trace


class Worker:
    """One thread, one job slot: a newer job replaces a waiting one (and cancels a running
    final one, _obsolete)."""

    def __init__(self):
        self.cv = threading.Condition()
        self.job = None
        self.tasks = []               # callables that must all run, in order (result writes)
        self.running = None
        self.results = []             # finished jobs' outputs, for the main thread
        self.thread = None
        self.stop = False

    def submit(self, job):
        with self.cv:
            self.job = job
            self._start()
            self.cv.notify_all()

    def submit_task(self, fn):
        """Runs fn() on the worker before any live job (F12's result write)."""
        with self.cv:
            self.tasks.append(fn)
            self._start()
            self.cv.notify_all()

    def _start(self):
        if self.thread is None or not self.thread.is_alive():
            self.stop = False
            self.thread = threading.Thread(target=self._loop, name="libfx live", daemon=True)
            self.thread.start()

    def idle(self):
        with self.cv:
            return self.job is None and not self.tasks and self.running is None

    def wait_idle(self, timeout):
        end = time.monotonic() + timeout
        with self.cv:
            while self.job is not None or self.tasks or self.running is not None:
                left = end - time.monotonic()
                if left <= 0:
                    return False
                self.cv.wait(left)
        return True

    def take_results(self):
        """The finished jobs' outputs since the last call (main thread)."""
        with self.cv:
            out, self.results = self.results, []
        return out

    def shutdown(self):
        with self.cv:
            self.stop = True
            self.job = None
            tasks, self.tasks = self.tasks, []
            self.cv.notify_all()
        for fn in tasks:   # result writes are never dropped
            _run_task(fn)

    def _loop(self):
        while True:
            with self.cv:
                while self.job is None and not self.tasks and not self.stop:
                    self.cv.wait()
                if self.stop:
                    return
                task = self.tasks.pop(0) if self.tasks else None
                if task is not None:
                    self.running = task
            if task is not None:
                _run_task(task)
                with self.cv:
                    self.running = None
                    self.cv.notify_all()
                continue
            with self.cv:
                job, self.job = self.job, None
                if job is None:
                    continue
                self.running = job
            try:
                trace("job %s start" % job.kind)
                out = job.run(lambda: self._obsolete(job))
                trace("job %s end" % job.kind)
            except Exception as e:  # never let the thread die
                out = {"job": job, "error": "%s: %s" % (type(e).__name__, e)}
            with self.cv:
                self.running = None
                if out is not None:
                    self.results.append(out)
                self.cv.notify_all()

    def _obsolete(self, job):
        """A newer change cancels a running final run (hundreds of ms), but not a running
        interactive one: during a drag a change comes every few tens of ms, about what an
        interactive run takes, so cancelling those would leave the image still until the
        drag ends. The interactive run finishes and shows; the newest change runs next."""
        with self.cv:
            if self.stop:
                return True
            return self.job is not None and self.job.generation > job.generation and job.kind != "interactive"


WORKER = Worker()


def _run_task(fn):
    try:
        fn()
    except Exception as e:
        log("live: background task failed: %s: %s" % (type(e).__name__, e))
