"""What a command shows while it runs: a progress bar over the frame graph's passes, and one line
when Warp is about to compile kernels (a cold kernel cache)."""

from __future__ import annotations

import sys
import threading
import time


class PassProgress:
    """A progress bar over the frame graph's passes (the ``progress`` callable of
    :func:`wsoft.render` and :func:`wsoft.compare`), on stderr.

    Shown only when stderr is a terminal and the render has run :attr:`delay_s` seconds, so short
    renders and piped or redirected output stay quiet; a ticker redraws it (elapsed time) during a
    long pass such as the reference's. Use it as a context manager."""

    delay_s = 2.0

    def __init__(self, desc: str, stream=None):
        self.desc = desc
        self.stream = stream if stream is not None else sys.stderr
        isatty = getattr(self.stream, "isatty", None)
        self.enabled = bool(isatty and isatty())
        self.bar = None
        self._pass: str | None = None
        self._compiling: str | None = None
        self._start = time.monotonic()
        self._stop = threading.Event()
        self._ticker: threading.Thread | None = None

    def __call__(self, done: int, total: int, name: str | None) -> None:
        if not self.enabled:
            return
        if self.bar is None:
            from tqdm import tqdm

            self.bar = tqdm(total=total, desc=self.desc, file=self.stream, leave=False, dynamic_ncols=True,
                            delay=max(0.0, self.delay_s - (time.monotonic() - self._start)),
                            bar_format="{desc}: {percentage:3.0f}%|{bar}| {n_fmt}/{total_fmt} passes [{elapsed}{postfix}]")  # no rate: passes differ
            self._ticker = threading.Thread(target=self._tick, name="wsoft-progress", daemon=True)
            self._ticker.start()
        self._pass, self._compiling = name, None
        self.bar.set_postfix_str(name or "done", refresh=False)
        self.bar.update(done - self.bar.n)

    def compiling(self, module: str) -> None:
        """Show that Warp compiles ``module`` during the current pass."""
        self._compiling = module
        if self.bar is not None:
            shown = time.monotonic() - self._start >= self.delay_s  # the bar is on the screen: say it at once
            self.bar.set_postfix_str(f"{self._pass or ''} (compiling {module})", refresh=shown)

    def _tick(self) -> None:
        while not self._stop.wait(0.5):
            if time.monotonic() - self._start >= self.delay_s:
                self.bar.refresh()

    def close(self) -> None:
        self._stop.set()
        if self._ticker is not None:
            self._ticker.join()
        if self.bar is not None:
            self.bar.close()

    def __enter__(self) -> "PassProgress":
        global _PROGRESS
        _PROGRESS = self
        return self

    def __exit__(self, *exc) -> None:
        global _PROGRESS
        _PROGRESS = None
        self.close()


_PROGRESS: PassProgress | None = None  # the bar shown now, which CompileNotice tells what compiles


def busy() -> str:
    """``; longer now: load 11.3 on 2 cores`` when the 1-minute load average exceeds the cores this
    process may use (compiling then takes longer than its estimate), else ``""``."""
    import os

    try:
        load, cores = os.getloadavg()[0], len(os.sched_getaffinity(0))
    except (AttributeError, OSError):  # pragma: no cover - no load average on this platform
        return ""
    return f"; longer now: load {load:.1f} on {cores} core{'s' if cores > 1 else ''}" if load > cores else ""


class CompileNotice:
    """While it is entered, the first time Warp is about to compile a module (its binary is not in
    the kernel cache) one line goes to stderr: ``compiling kernels for cpu (first run only, ~8 s on
    an idle core)``, the time a rough estimate from the modules not yet compiled for the device
    (:func:`wsoft.parallel.uncached_seconds`: the render's own modules and, where ``techniques``
    names the ones that run, the modules their code refers to), with the load average when the
    machine is busier than its cores. The progress bar, when shown, names each module that
    compiles. A warm cache prints nothing."""

    def __init__(self, device: str | None, techniques: list[str] | None = None, stream=None):
        from wsoft.parallel import resolve_device, uncached_seconds
        from wsoft.techniques import NAMES, TECHNIQUES

        TECHNIQUES  # noqa: B018  (the technique modules define their kernels on import)
        self.device = resolve_device(device)
        skip = () if techniques is None else tuple(f"wsoft.techniques.{n}" for n in NAMES if n not in techniques)
        self.seconds = uncached_seconds(self.device, skip, techniques)
        self.stream = stream if stream is not None else sys.stderr
        self.said = False
        self._lock = threading.Lock()
        self._remove = None

    def __call__(self, module: str, device: str) -> None:
        with self._lock:
            if not self.said:
                self.said = True
                about = f", ~{max(1, round(self.seconds))} s on an idle core{busy()}" if self.seconds else ""
                print(f"compiling kernels for {device} (first run only{about})", file=self.stream, flush=True)
        if _PROGRESS is not None:
            _PROGRESS.compiling(module)

    def __enter__(self) -> "CompileNotice":
        from wsoft.parallel import on_compile

        self._remove = on_compile(self)
        return self

    def __exit__(self, *exc) -> None:
        self._remove()
