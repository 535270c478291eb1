"""Progress reports: a callable(fraction) of the caller's, or tqdm (if installed) for True."""
from __future__ import annotations

import sys
from typing import Any, Callable, Optional


def progress_callback(progress: Any, label: str) -> Optional[Callable[[float], None]]:
    """None (quiet), a callable taking the fraction done in [0, 1], or True: a tqdm bar when
    tqdm is installed, else a one-line bar on stderr."""
    if progress is None or progress is False:
        return None
    if callable(progress):
        return progress
    if progress is True:
        try:
            from tqdm.auto import tqdm  # optional
        except ImportError:
            tqdm = None
        if tqdm is not None:
            bar = tqdm(total=1000, desc=label, leave=False)
            done = [0]

            def update(f: float) -> None:
                n = int(f * 1000)
                if n > done[0]:
                    bar.update(n - done[0])
                    done[0] = n
                if n >= 1000:
                    bar.close()
            return update

        shown = [-1]

        def text(f: float) -> None:  # whole percents only, one line ended once
            pct = int(100 * f)
            if pct <= shown[0]:
                return
            shown[0] = pct
            sys.stderr.write(f"\r{label}: {pct:3d} %" + ("\n" if pct >= 100 else ""))
            sys.stderr.flush()
        return text
    raise ValueError("progress must be None, True or a callable(fraction)")
