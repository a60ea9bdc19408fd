"""Measured Fourier-descriptor spectra: the CSV written by ``grainforge fourier``.

``grainforge fourier IMAGE... --csv fd.csv`` writes one row per grain with
the descriptors D2…D16 of its outline.  Generators that take ``spectrum``
(``rf``, ``cri``) read the table with :func:`read_spectra` and give each
generated grain the spectrum of one measured grain, drawn uniformly from the
grain's ``rng``, so that a generated population varies from grain to grain as
the measured one does.  Above D16 the spectrum is continued with
:func:`extend_spectrum`.

Examples
--------
>>> row = np.array([0.15, 0.1, 0.06, 0.05, 0.04, 0.035, 0.03] + [0.03 * (n / 8) ** (-5 / 3) for n in range(9, 17)])
>>> D = extend_spectrum(row, -5 / 3, 32)
>>> round(float(D[8]), 3), round(float(D[32] / D[16]), 4), round(2 ** (-5 / 3), 4)
(0.03, 0.315, 0.315)
"""

from __future__ import annotations

import csv
from dataclasses import dataclass
from functools import lru_cache
from pathlib import Path

import numpy as np

from ..params import ParameterError
from ..rng import RNGLike, as_generator

__all__ = ["MEASURED_ORDERS", "Spectra", "read_spectra", "extend_spectrum"]

#: the orders ``grainforge fourier`` writes (D2..D16)
MEASURED_ORDERS = tuple(range(2, 17))
#: orders over which the tail anchor of :func:`extend_spectrum` is fitted
TAIL_FIT = tuple(range(9, 17))


@dataclass(frozen=True, eq=False)
class Spectra:
    """The measured spectra of a ``grainforge fourier`` CSV.

    Attributes
    ----------
    path : str
    D : (G, 15) float64
        D2…D16 per measured grain (read-only).
    labels : tuple of str
        ``image#grain`` per row.
    """

    path: str
    D: np.ndarray
    labels: tuple[str, ...]

    def __len__(self) -> int:
        return len(self.D)

    def draw(self, rng: RNGLike) -> int:
        """The row of one measured grain, uniformly (one ``rng.integers`` draw).

        Parameters
        ----------
        rng : None, int, numpy.random.SeedSequence or numpy.random.Generator
            Normalised by :func:`grainforge.rng.as_generator`; a Generator is advanced by one draw.

        Returns
        -------
        int
            A row index into ``D`` and ``labels``.
        """
        return int(as_generator(rng).integers(len(self.D)))


@lru_cache(maxsize=16)
def _read(path: str, mtime_ns: int, size: int, name: str) -> Spectra:
    cols = [f"D{n}" for n in MEASURED_ORDERS]
    try:
        with open(path, newline="", encoding="utf-8") as fh:
            reader = csv.DictReader(fh)
            missing = [c for c in cols if c not in (reader.fieldnames or [])]
            if missing:
                raise ParameterError(
                    name, f"{path}: not a 'grainforge fourier' CSV (missing column(s) {', '.join(missing)})"
                )
            rows, labels = [], []
            for k, rec in enumerate(reader):
                try:
                    vals = [float(rec[c]) for c in cols]
                except (TypeError, ValueError):
                    raise ParameterError(name, f"{path}: row {k + 2} has a non-numeric descriptor") from None
                if not all(np.isfinite(vals)) or min(vals) < 0:
                    raise ParameterError(name, f"{path}: row {k + 2} has a negative or non-finite descriptor")
                rows.append(vals)
                labels.append(f"{rec.get('image', '')}#{rec.get('grain', k)}")
    except (OSError, UnicodeDecodeError, csv.Error) as exc:
        raise ParameterError(name, f"{path}: cannot read ({exc.__class__.__name__}: {exc})") from None
    if not rows:
        raise ParameterError(name, f"{path}: has no grain rows")
    D = np.array(rows, dtype=np.float64)
    D.setflags(write=False)
    return Spectra(path, D, tuple(labels))


def read_spectra(path: str | Path, name: str = "spectrum") -> Spectra:
    """Read (and cache, by path, size and modification time) a ``grainforge fourier`` CSV.

    Parameters
    ----------
    path : str or Path
        The CSV written by ``grainforge fourier --csv`` (columns D2 … D16, optional ``image`` and ``grain``).
    name : str, default "spectrum"
        The parameter the errors name (the CLI's ``--spectrum``).

    Returns
    -------
    Spectra
        Read-only; the same object again while the file is unchanged.

    Raises
    ------
    ParameterError
        Named ``name``: missing or unreadable file, missing D2…D16 columns, no
        rows, or a negative / non-numeric descriptor.
    """
    p = Path(path)
    if not p.is_file():
        raise ParameterError(name, f"{path}: no such file")
    st = p.stat()
    return _read(str(p.resolve()), st.st_mtime_ns, st.st_size, name)


def extend_spectrum(measured: np.ndarray, decay: float, modes: int) -> np.ndarray:
    """A full amplitude spectrum D_0…D_modes from measured D2…D16.

    D_0 = 1, D_1 = 0, D2…D16 as measured (truncated if ``modes`` < 16), and
    above 16 the power law D_n = A (n/16)^β, β = ``decay`` (the second CRI
    decay exponent), with the anchor A fitted in log space to D9…D16 (a single
    measured D16 is too noisy to anchor the tail on).

    Parameters
    ----------
    measured : (15,) float64
        D2…D16.
    decay : float
        β ≤ 0.
    modes : int
        Highest order N ≥ 2.

    Returns
    -------
    (modes + 1,) float64
        D_0 … D_modes, relative to the mean radius.
    """
    d = np.asarray(measured, dtype=np.float64)
    D = np.zeros(modes + 1)
    D[0] = 1.0
    top = min(modes, 16)
    D[2 : top + 1] = d[: top - 1]
    if modes > 16:
        n = np.asarray(TAIL_FIT, dtype=np.float64)
        tail = np.maximum(d[np.asarray(TAIL_FIT) - 2], 1e-12)
        anchor = float(np.exp(np.mean(np.log(tail) - decay * np.log(n / 16.0))))
        D[17:] = anchor * (np.arange(17, modes + 1) / 16.0) ** decay
    return D
