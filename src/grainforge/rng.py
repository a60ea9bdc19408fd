"""The one way a public function takes randomness: an ``rng`` argument.

Every public function of grainforge that draws random numbers takes ``rng``, which may be

- ``None``: fresh entropy from the operating system (the seed drawn is still returned by
  :func:`resolve_rng`, so a grain made this way can be regenerated);
- an ``int`` seed (non-negative): ``numpy.random.default_rng(seed)``;
- a :class:`numpy.random.SeedSequence`: ``numpy.random.default_rng(sequence)``;
- a :class:`numpy.random.Generator`: used as it is, and advanced by the draws.

:func:`as_generator` and :func:`resolve_rng` are the only places that turn such a value into a
Generator; :func:`seed_sequence` turns it into a SeedSequence for code that spawns independent child
streams.  There is no global random state anywhere in the package.

>>> import numpy as np
>>> float(as_generator(7).random()) == float(np.random.default_rng(7).random())
True
>>> g = np.random.default_rng(1)
>>> as_generator(g) is g
True
>>> resolve_rng(np.random.SeedSequence(5))[1]
5
"""

from __future__ import annotations

from typing import TypeAlias

import numpy as np

from .errors import InputError

__all__ = ["RNGLike", "as_generator", "resolve_rng", "seed_sequence"]

#: what a public ``rng`` argument accepts
RNGLike: TypeAlias = None | int | np.integer | np.random.SeedSequence | np.random.Generator


def _seed(value: int | np.integer) -> int:
    seed = int(value)
    if seed < 0:
        raise InputError(f"seed must be a non-negative integer, got {seed}")
    return seed


def resolve_rng(rng: RNGLike) -> tuple[np.random.Generator, int | None]:
    """Normalise ``rng`` to a Generator, returning the integer seed when there is one.

    Parameters
    ----------
    rng : None, int, numpy.random.SeedSequence or numpy.random.Generator
        ``None`` draws fresh entropy from the operating system and records it as the seed, so the
        result can be regenerated; an int is a seed (non-negative); a SeedSequence seeds a new
        Generator; a Generator is returned as it is (and will be advanced by the caller's draws).

    Returns
    -------
    generator : numpy.random.Generator
        The stream to draw from.
    seed : int or None
        The seed that regenerates ``generator``'s stream: ``rng`` itself for an int, the entropy
        drawn for ``None``, the entropy of a SeedSequence that has no spawn key and an integer
        entropy; ``None`` for a Generator or a spawned SeedSequence (no single int reproduces it).

    Raises
    ------
    ValueError
        If ``rng`` is a negative int, or none of the accepted kinds (bool, float, str, a list of
        seeds, a legacy ``RandomState``, ...).

    Examples
    --------
    >>> import numpy as np
    >>> g, seed = resolve_rng(3)
    >>> seed, float(g.random()) == float(np.random.default_rng(3).random())
    (3, True)
    >>> g, seed = resolve_rng(None)
    >>> float(g.random()) == float(np.random.default_rng(seed).random())
    True
    >>> resolve_rng(np.random.SeedSequence(3).spawn(1)[0])[1] is None
    True
    """
    if isinstance(rng, np.random.Generator):
        return rng, None
    if rng is None:
        rng = int(np.random.SeedSequence().entropy)
    if isinstance(rng, (int, np.integer)) and not isinstance(rng, (bool, np.bool_)):
        seed = _seed(rng)
        return np.random.default_rng(seed), seed
    if isinstance(rng, np.random.SeedSequence):
        plain = not rng.spawn_key and isinstance(rng.entropy, (int, np.integer))
        return np.random.default_rng(rng), (int(rng.entropy) if plain else None)
    raise InputError(
        f"rng must be None, a non-negative int, a numpy SeedSequence or a numpy Generator, got {rng!r}"
    )


def as_generator(rng: RNGLike) -> np.random.Generator:
    """The Generator for ``rng`` (:func:`resolve_rng` without the seed).

    Parameters
    ----------
    rng : None, int, numpy.random.SeedSequence or numpy.random.Generator
        As for :func:`resolve_rng`.

    Returns
    -------
    numpy.random.Generator
        ``rng`` itself when it is a Generator, else a new Generator seeded by it.

    Raises
    ------
    ValueError
        If ``rng`` is a negative int or none of the accepted kinds.

    Examples
    --------
    >>> as_generator(0).integers(10, size=3).tolist()
    [8, 6, 5]
    """
    return resolve_rng(rng)[0]


def seed_sequence(rng: RNGLike) -> np.random.SeedSequence:
    """The SeedSequence for ``rng``, for code that spawns independent child streams.

    Parameters
    ----------
    rng : None, int, numpy.random.SeedSequence or numpy.random.Generator
        An int ``s`` gives ``SeedSequence(s)`` (so ``seed_sequence(s).spawn(n)`` are the children
        a plain seed has always given); a SeedSequence is returned as it is; ``None`` gives fresh
        entropy; a Generator gives the SeedSequence of one 128-bit draw from it (advancing it).

    Returns
    -------
    numpy.random.SeedSequence

    Raises
    ------
    ValueError
        If ``rng`` is a negative int or none of the accepted kinds.

    Examples
    --------
    >>> seed_sequence(7).entropy
    7
    >>> a = seed_sequence(np.random.default_rng(1)).entropy
    >>> a == seed_sequence(np.random.default_rng(1)).entropy
    True
    """
    if isinstance(rng, np.random.SeedSequence):
        return rng
    if isinstance(rng, np.random.Generator):
        return np.random.SeedSequence([int(x) for x in rng.integers(0, 2**32, size=4, dtype=np.uint64)])
    if rng is None:
        return np.random.SeedSequence()
    if isinstance(rng, (int, np.integer)) and not isinstance(rng, (bool, np.bool_)):
        return np.random.SeedSequence(_seed(rng))
    raise InputError(
        f"rng must be None, a non-negative int, a numpy SeedSequence or a numpy Generator, got {rng!r}"
    )
