"""Long work without freezing Blender: jobs that read Blender data on the main thread, hand the numpy/Vulkan work
to a worker thread, and write their results back on the main thread.

A job is a generator. What it runs between its yields runs on the main thread (it may use bpy). It yields:

- ``Step(text, fraction)``: where it is; a Runner lets Blender draw the window before going on.
- ``Work(fn, *args, **kwargs)``: ``fn(*args, **kwargs, progress=...)`` runs on a worker thread holding ``gpu`` (numpy
  and Vulkan only: bpy is not thread-safe), and the generator resumes with its return value, or with its exception
  raised at the yield. ``progress(text, fraction)`` is what core functions already take.

The generator's return value is the job's result. Two drivers run the same generators:

- ``run_now(job)``: in the calling thread, Work inline (scripts, ``blender -b``, operators' execute(), tests).
- ``Runner``: advanced by timer ticks (modal operators, Update When Moved, the overlay's first upload). Each tick
  runs main-thread parts until the job yields; Work runs beside the UI. ``cancel()`` (Esc) makes the worker's
  next progress call raise Cancelled and then closes the generator (GeneratorExit at its yield, so its finally
  blocks run). Jobs write Blender data only after their last Work, so a cancelled job leaves nothing half-made.

``gpu`` is one lock for every use of the shared Vulkan renderers (bakes, uploads, the overlay's renders): a worker
holds it for the whole of its Work, and the overlay, which draws on the main thread, draws its last images
instead of waiting for it.
"""
from __future__ import annotations

import threading
import time
from dataclasses import dataclass, field
from typing import Any, Callable, Generator

Progress = Callable[[str, float], None]
Job = Generator[Any, Any, Any]

gpu = threading.RLock()  # held while the shared renderers are in use (see above)


class Cancelled(Exception):
    """Raised inside a worker by its progress callback once its job was cancelled."""


@dataclass
class Step:
    text: str
    fraction: float | None = None  # of the whole job; None: unchanged
    # the job waits for this other job (a background one): a Runner gives the rest of its tick back to Blender,
    # whose timer advances the other; run_now, which holds the main thread, advances the other itself
    wait_for: "Runner | None" = None


@dataclass
class Work:
    """``fn(*args, **kwargs, progress=...)`` on a worker thread; ``span``: the part of the job's progress it fills;
    ``uses_gpu=False`` for work that leaves the shared renderers alone (reading a file): the overlay keeps drawing."""
    fn: Callable[..., Any]
    args: tuple = ()
    kwargs: dict = field(default_factory=dict)
    span: tuple[float, float] | None = None
    uses_gpu: bool = True

    def __init__(self, fn: Callable[..., Any], *args, span: tuple[float, float] | None = None,
                 uses_gpu: bool = True, **kwargs) -> None:
        self.fn, self.args, self.kwargs, self.span, self.uses_gpu = fn, args, kwargs, span, uses_gpu

    def __call__(self, progress: Progress) -> Any:
        """Run it here (the caller's thread), holding ``gpu`` when it uses the GPU."""
        if not self.uses_gpu:
            return self.fn(*self.args, **self.kwargs, progress=_scaled(progress, self.span))
        with gpu:
            return self.fn(*self.args, **self.kwargs, progress=_scaled(progress, self.span))


def _into(a: float, b: float, fraction: float) -> float:
    """``fraction`` of a part's own progress (clamped to [0, 1]) as its caller's, the part being [a, b] of it."""
    return a + (b - a) * min(max(float(fraction), 0.0), 1.0)


def _scaled(progress: Progress, span: tuple[float, float] | None) -> Progress:
    if span is None:
        return progress
    a, b = span
    return lambda text, fraction: progress(text, _into(a, b, fraction))


def within(job: Job, a: float, b: float) -> Job:
    """``job`` run as the part [a, b] of its caller's progress (``x = yield from within(sub, 0.4, 0.9)``): its Step
    fractions and Work spans are mapped into [a, b] (a Work without a span fills all of it), so a job made of parts
    says 100% only at its end (a bake's status line once read 100% for the 18 s of Lighting Auto after its span).
    Errors thrown in at a yield and closing go through to ``job``; returns its result."""
    value, error = None, None
    while True:
        try:
            item = job.throw(error) if error is not None else job.send(value)
        except StopIteration as stop:
            return stop.value
        value = error = None
        if isinstance(item, Step) and item.fraction is not None:
            item = Step(item.text, _into(a, b, item.fraction), item.wait_for)
        elif isinstance(item, Work):
            lo, hi = item.span or (0.0, 1.0)
            item.span = (_into(a, b, lo), _into(a, b, hi))
        try:
            value = yield item
        except GeneratorExit:
            job.close()
            raise
        except BaseException as e:  # noqa: BLE001  handed to the sub-job, as yield from would
            error = e


def run_now(job: Job, progress: Progress | None = None) -> Any:
    """Run ``job`` to its end in this thread; returns its result, raises its error."""
    say = progress or (lambda _text, _fraction: None)
    value, error = None, None
    while True:
        try:
            item = job.throw(error) if error is not None else job.send(value)
        except StopIteration as stop:
            return stop.value
        value = error = None
        if isinstance(item, Step):
            say(item.text, item.fraction if item.fraction is not None else 0.0)
            while item.wait_for is not None and not item.wait_for.tick():
                time.sleep(0.01)  # its timer cannot run while this thread is here
        elif isinstance(item, Work):
            try:
                value = item(say)
            except Exception as e:  # noqa: BLE001  handed to the job, which decides
                error = e
        else:
            job.close()
            raise TypeError(f"a job yielded {item!r}: only Step and Work")


MAX_RUNNING = 0.99  # the most a running job's status line says: 100% is for a job that has ended


class Runner:
    """Runs one job a tick at a time (see the module's docstring). ``text`` and ``fraction`` say where it is;
    after ``tick()`` returned True, ``result``, ``error`` or ``cancelled`` say how it ended."""

    def __init__(self, job: Job, title: str = "", escapable: bool = False) -> None:
        self.job, self.title, self.escapable = job, title, escapable  # escapable: a modal operator's (Esc)
        self.text, self.fraction = "starting", 0.0
        self.done = self.cancelled = False
        self.result: Any = None
        self.error: BaseException | None = None
        self.started = time.perf_counter()
        self._cancel = threading.Event()
        self._thread: threading.Thread | None = None
        self._outcome: tuple[Any, BaseException | None] = (None, None)
        self._span: tuple[float, float] | None = None

    def _advance(self, fraction: float) -> None:
        """The status line's fraction never goes back (a part may restart its own count: the core's face-size search
        renders a larger size after a smaller) and says 100% only once the job has ended (MAX_RUNNING below)."""
        self.fraction = min(max(self.fraction, float(fraction)), MAX_RUNNING)

    # ---- called from the worker
    def _progress(self, text: str, fraction: float) -> None:
        if self._cancel.is_set():
            raise Cancelled(text)
        self.text = text
        self._advance(fraction)

    def _work(self, item: Work) -> None:
        try:
            self._outcome = (item(self._progress), None)
        except BaseException as e:  # noqa: BLE001  handed to the main thread
            self._outcome = (None, e)

    # ---- called from the main thread
    @property
    def working(self) -> bool:
        """A worker is running."""
        return self._thread is not None

    def cancel(self) -> None:
        """Stop as soon as the worker's next progress call (or now, between Work): nothing more is written."""
        self._cancel.set()
        if self._thread is None and not self.done:
            self._end_cancelled()

    def _end_cancelled(self) -> None:
        self.job.close()
        self.done = self.cancelled = True
        self.text = "cancelled"

    def tick(self, budget_s: float = 0.05) -> bool:
        """Advance the job: main-thread parts until it yields a Step (the window gets drawn), starts Work, or has
        used ``budget_s``; returns True once it has ended. Never raises: a failure ends the job with ``error`` (a
        timer or modal handler that raised would be dropped by Blender with the job still listed as running)."""
        try:
            return self._tick(budget_s)
        except Exception as e:  # noqa: BLE001
            self.error, self.done = e, True
            return True

    def _tick(self, budget_s: float) -> bool:
        until = time.perf_counter() + budget_s
        while not self.done:
            if self._thread is not None:
                if self._thread.is_alive():
                    return False
                self._thread.join()
                self._thread = None
                value, error = self._outcome
                self._outcome = (None, None)
            else:
                value, error = None, None
            if self._cancel.is_set():
                self._end_cancelled()
                break
            try:
                item = self.job.throw(error) if error is not None else self.job.send(value)
            except StopIteration as stop:
                self.result, self.done, self.fraction = stop.value, True, 1.0
                break
            except Exception as e:  # noqa: BLE001  the job's own error: the caller reports it
                self.error, self.done = e, True
                break
            if isinstance(item, Step):
                self.text = item.text
                if item.fraction is not None:
                    self._advance(item.fraction)
                if item.wait_for is not None or time.perf_counter() >= until:
                    return False
            elif isinstance(item, Work):
                self._thread = threading.Thread(target=self._work, args=(item,), daemon=True,
                                                name=f"gs-ibl {self.title}")
                self._thread.start()
                return False
            else:
                self.job.close()
                self.error, self.done = TypeError(f"a job yielded {item!r}: only Step and Work"), True
        return True

    def status(self) -> str:
        """One line for the status bar: what, where, how far, how to stop."""
        if self._cancel.is_set():
            return f"GS-IBL {self.title}: cancelling (waiting for the current step to end)"
        return (f"GS-IBL {self.title}: {self.text} - {100 * self.fraction:.0f}%, "
                f"{time.perf_counter() - self.started:.0f} s" + (" (Esc to cancel)" if self.escapable else ""))


# ---------------------------------------------------------------------------------------- background jobs (timers)

TICK_S = 0.1  # how often a background job or a modal operator looks at its worker: the UI redraws in between
_background: dict[str, Runner] = {}  # key -> running job (one per key: a new one cancels the old)


def show_status(text: str | None, sidebars: bool = False) -> None:
    """Put ``text`` in the status bar of every window (None gives the status bar back to Blender); ``sidebars``:
    also redraw the 3D Views' sidebars, whose GS-IBL panel lists running jobs. Only when that list changes: with
    Region Overlap (the default) a sidebar's redraw redraws the viewport under it, overlay and all, which at once a
    second took as much CPU as the bake it reported on (capture_bench, 2026-12-03)."""
    import bpy
    for window in getattr(bpy.context.window_manager, "windows", []):
        workspace = window.workspace
        if workspace is None:
            continue
        with bpy.context.temp_override(window=window):  # a timer's context has no window of its own
            workspace.status_text_set(text)
        if not sidebars:
            continue
        for area in window.screen.areas:
            if area.type == "VIEW_3D":
                for region in area.regions:
                    if region.type == "UI":
                        region.tag_redraw()


_listed: list[str] = []  # the titles of the jobs the sidebars last listed
_notices: dict[str, str] = {}  # key -> a line the status bar shows after the running jobs' (set_notice)


def set_notice(key: str, text: str | None) -> None:
    """Show ``text`` in the status bar (after any running job's line) until it is set to None; e.g. "the bake of
    'Probe' is out of date". Redraws only when it changes (callers may call it at every depsgraph update)."""
    if _notices.get(key) == text:
        return
    if text is None:
        del _notices[key]
    else:
        _notices[key] = text
    _status_now()


def notices() -> list[str]:
    """The status bar's notices now (tests read them)."""
    return list(_notices.values())


def _status_now() -> None:
    runners = running()
    titles = [r.title for r in runners]
    lines = [r.status() for r in runners] + list(_notices.values())
    show_status("    ".join(lines) if lines else None, sidebars=titles != _listed)
    _listed[:] = titles


def start(key: str, job: Job, title: str, done: Callable[[Runner], None] | None = None) -> Runner | None:
    """Run ``job`` in the background, driven by a timer, and call ``done(runner)`` on the main thread when it
    ends. Without a window (``blender -b``, the bpy module) there is no event loop to drive timers and no UI to keep
    responsive: it runs now, and done() is called before this returns. Returns the runner (None when run now)."""
    import bpy
    old = _background.pop(key, None)
    if old is not None:
        old.cancel()  # its worker notices at its next progress call; its timer still drains it
    runner = Runner(job, title)
    if bpy.app.background:
        try:
            runner.result = run_now(job)
        except Exception as e:  # noqa: BLE001
            runner.error = e
        runner.done = True
        if done is not None:
            done(runner)
        return None
    _background[key] = runner

    def step() -> float | None:
        if not runner.tick():
            _status_now()
            return TICK_S
        if _background.get(key) is runner:
            del _background[key]
        _status_now()
        if done is not None and not runner.cancelled:
            done(runner)
        return None

    bpy.app.timers.register(step, first_interval=0.0)
    return runner


def busy(key: str) -> Runner | None:
    """The background job running under ``key``, if any."""
    return _background.get(key)


def cancel_all() -> None:
    """Cancel every job (a file is loaded, the extension is disabled): their results would land in data that is no
    longer there. Loading a file also drops modal handlers without telling them: their jobs are forgotten here, or
    their operator would refuse to run again ("already baking")."""
    for runner in list(_background.values()) + list(_modal.values()):
        runner.cancel()
    _background.clear()
    _modal.clear()
    if _notices:  # about the file being closed
        _notices.clear()
        _status_now()


# ------------------------------------------------------------------------------------------------ modal operators

USER_ERRORS = (ValueError, RuntimeError, OSError, MemoryError)  # core errors carry a message meant for the user
_NAVIGATION = {"MOUSEMOVE", "INBETWEEN_MOUSEMOVE", "MIDDLEMOUSE", "WHEELUPMOUSE", "WHEELDOWNMOUSE", "WHEELINMOUSE",
               "WHEELOUTMOUSE", "TRACKPADPAN", "TRACKPADZOOM", "MOUSEROTATE", "MOUSESMARTZOOM", "WINDOW_DEACTIVATE",
               "TIMER", "TIMER_REPORT", "NONE"}


class JobOperator:
    """Mixin for an operator whose work is a job: ``execute()`` runs it now (scripts, ``blender -b``, the Redo
    panel); ``invoke()`` runs it modally: Blender's progress in the cursor and a status-bar line with the stage and
    percentage, the viewport drawn and navigable meanwhile, Esc cancels with nothing changed. Other input waits
    until the job ends: an edit or an undo under a running job would pull its data away.

    Subclasses give ``job_title``, ``make_job(context)`` (check everything and raise a ValueError before any work;
    return the job) and ``finished(context, result)`` (report; return the operator's set)."""

    job_title = "working"
    _runner: Runner | None = None
    _timer = None

    def make_job(self, context) -> Job:
        raise NotImplementedError

    def finished(self, context, result) -> set[str]:
        return {"FINISHED"}

    def execute(self, context):
        import bpy

        def say(text: str, _fraction: float) -> None:
            if bpy.app.background:  # headless: the console is the only progress bar
                print(f"GS-IBL: {text}")

        try:
            result = run_now(self.make_job(context), say)
        except USER_ERRORS as e:
            self.report({"ERROR"}, str(e))
            return {"CANCELLED"}
        return self.finished(context, result)

    def invoke(self, context, event):
        import bpy
        if bpy.app.background or context.window is None:
            return self.execute(context)
        key = type(self).__name__
        if key in _modal:
            self.report({"ERROR"}, f"GS-IBL is already {self.job_title} (Esc cancels it)")
            return {"CANCELLED"}
        try:
            job = self.make_job(context)
        except USER_ERRORS as e:
            self.report({"ERROR"}, str(e))
            return {"CANCELLED"}
        self._runner = Runner(job, self.job_title, escapable=True)
        _modal[key] = self._runner
        wm = context.window_manager
        self._timer = wm.event_timer_add(TICK_S, window=context.window)
        wm.modal_handler_add(self)
        wm.progress_begin(0, 100)
        self._show(context)
        return {"RUNNING_MODAL"}

    def _show(self, context) -> None:
        context.window_manager.progress_update(int(100 * self._runner.fraction))
        _status_now()

    def modal(self, context, event):
        r = self._runner
        if event.type == "ESC" and event.value == "PRESS":
            r.cancel()
        elif event.type == "TIMER":  # ours or another's: ticking more often does no harm
            r.tick()
        if not r.done:
            self._show(context)
            navigation = event.type in _NAVIGATION or event.type.startswith(("NUMPAD_", "NDOF_"))
            return {"PASS_THROUGH"} if navigation else {"RUNNING_MODAL"}
        wm = context.window_manager
        wm.event_timer_remove(self._timer)
        wm.progress_end()
        _modal.pop(type(self).__name__, None)
        _status_now()
        from .redraw import tag_redraw  # the overlay drew its last images while the worker held the GPU
        tag_redraw()
        if r.cancelled:
            self.report({"WARNING"}, f"GS-IBL {self.job_title}: cancelled, nothing was changed")
            return {"CANCELLED"}
        if r.error is not None:
            if not isinstance(r.error, USER_ERRORS):
                raise r.error
            self.report({"ERROR"}, str(r.error))
            return {"CANCELLED"}
        return self.finished(context, r.result)


_modal: dict[str, Runner] = {}  # operator class name -> its running job (one at a time per operator)


def modal_running() -> bool:
    """A modal job (a bake or an import the user started and can Esc) is running: background work that would
    compete with it for the GPU or the CPU (an overlay frame) waits until it ends."""
    return bool(_modal)


def running() -> list[Runner]:
    """Every job running now, modal and background (the panel and tests read it)."""
    return list(_modal.values()) + list(_background.values())
