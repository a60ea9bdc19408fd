"""A command's several outputs, written under temporary names and moved into place together."""

from __future__ import annotations

import os
import shutil
import tempfile
from pathlib import Path

from ..runtime.staging import commit_stage, discard_stage, open_stage, signals_held
from . import file_mode

__all__ = ["OutputSet"]


class OutputSet:
    """A command's outputs written under temporary names and renamed into place together at the end.

    :meth:`temp` gives a temporary file beside each final file; :meth:`mesh_stage` a staging folder for a
    folder of files (``grain-*.stl``) that replaces an earlier run's with ``overwrite``; :meth:`commit`
    moves everything into place with signals held; :meth:`discard` (call it in ``finally``) removes
    whatever was not committed, so a failure or an interrupt leaves nothing.
    """

    def __init__(self) -> None:
        self.temps: list[Path] = []
        self.moves: list[tuple[Path, Path]] = []
        self.stage: Path | None = None
        self.mesh_dir: Path | None = None
        self.mesh_created = False
        self.overwrite = False

    def temp(self, final: Path) -> Path:
        """
        Parameters
        ----------
        final : Path
            Where the file goes on :meth:`commit` (its folder is created).

        Returns
        -------
        Path
            A new empty temporary file beside ``final``, to write.
        """
        final.parent.mkdir(parents=True, exist_ok=True)
        with signals_held():  # the file is made and noted for the clean-up together: a signal waits for both
            fd, tmp = tempfile.mkstemp(prefix=f".{final.name}.", suffix=".tmp", dir=final.parent)
            os.close(fd)
            self.temps.append(Path(tmp))
            self.moves.append((Path(tmp), final))
        return Path(tmp)

    def mesh_stage(self, folder: Path, overwrite: bool) -> Path:
        """
        Parameters
        ----------
        folder : Path
            The mesh folder the staged files go into on :meth:`commit`.
        overwrite : bool
            On commit, remove an earlier run's ``grain-*.stl`` files that this run does not replace.

        Returns
        -------
        Path
            The staging folder to write the files into.
        """
        self.mesh_created = not folder.exists()
        self.mesh_dir, self.overwrite = folder, overwrite
        self.stage = open_stage(folder)[0]
        return self.stage

    def commit(self) -> None:

        with signals_held():
            for tmp, final in self.moves:
                os.chmod(tmp, file_mode())
                os.replace(tmp, final)
            self.temps = []
            if self.stage is not None:
                new = {p.name for p in self.stage.iterdir()}
                if self.overwrite:  # an earlier run's grain meshes that this one does not replace
                    for old in self.mesh_dir.glob("grain-*.stl"):
                        if old.name not in new:
                            old.unlink()
                commit_stage(self.stage, self.mesh_dir, overwrite=self.overwrite)
                shutil.rmtree(self.stage, ignore_errors=True)
                self.stage = None

    def discard(self) -> None:
        for tmp in self.temps:
            try:
                tmp.unlink()
            except FileNotFoundError:
                pass
        if self.mesh_dir is not None:
            discard_stage(self.stage, self.mesh_dir, self.mesh_created)
