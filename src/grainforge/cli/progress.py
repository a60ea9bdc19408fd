"""Progress bars on stderr (hidden when stderr is not a terminal)."""

from __future__ import annotations

from collections.abc import Callable, Iterable


def progress_bar(total: int | None = None, desc: str = "", unit: str = "grain") -> Callable[[Iterable], Iterable]:
    """A wrapper that shows a tqdm bar (count, rate and ETA) on stderr while iterating."""

    def wrap(it: Iterable) -> Iterable:
        from tqdm import tqdm

        return tqdm(it, total=total, desc=desc, unit=unit, disable=None, leave=False, dynamic_ncols=True)

    return wrap
