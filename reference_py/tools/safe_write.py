"""The safe writer of every output the Python tools produce (nte-ref, nte-bench,
nte-discrepancy).

* Only regular files are written.  A directory, device node (``/dev/null``), FIFO or socket
  given as an output is refused, never replaced.
* A symbolic link is written through: its target is replaced (the link stays a link); a link
  whose target's directory does not exist is refused like any missing directory.
* A file that is replaced keeps its permission bits (and, when the process may, its owner);
  a new file gets 0666 minus the umask, as ``open()`` would give it.
* No directory is created except one the command was asked to create
  (:meth:`Outputs.directory`, e.g. ``nte-bench replay --out DIR``), and then only that one
  level: ``/nonexistent/dir/x.csv`` is refused naming ``/nonexistent/dir``.
* All outputs of one command are committed together or not at all: each is written to a
  temporary file in its target's directory (created when the output is declared, so an
  unwritable place is refused before any work), and :meth:`Outputs.commit` renames them
  all at the end; on any error every temporary file is removed, files replaced so far are
  restored from hard-link backups, and a directory the command created is removed.
Refusals are :class:`OutputError` (``FLAG PATH: reason``), a ``ValueError``, so a CLI turns
them into one line on stderr and exit status 2 like a refused input (``csvio.CsvError``).
"""
from __future__ import annotations

import os
import stat
import tempfile
from dataclasses import dataclass
from pathlib import Path
from typing import Iterable


class OutputError(ValueError):
    """An output that cannot be written: the message names the flag, the path and why."""


_KINDS = ((stat.S_ISDIR, "a directory"), (stat.S_ISCHR, "a character device"),
          (stat.S_ISBLK, "a block device"), (stat.S_ISFIFO, "a FIFO"),
          (stat.S_ISSOCK, "a socket"))


def _umask() -> int:
    old = os.umask(0o022)
    os.umask(old)
    return old


def resolve_output(path: str | os.PathLike[str], flag: str = "--out") -> Path:
    """The regular file an output path will replace or create (symlinks followed), or
    OutputError if it is not a regular file or its directory does not exist."""
    given = Path(path)
    where = f"{flag} {given}" if flag else str(given)
    if str(path) == "":
        raise OutputError(f"{flag}: empty path")
    target = Path(os.path.realpath(given)) if given.is_symlink() else given
    try:
        st = os.stat(target)
    except FileNotFoundError:
        st = None
    except NotADirectoryError:
        st = None
    except OSError as exc:
        raise OutputError(f"{where}: {exc.strerror or exc}") from None
    if st is not None:
        for test, kind in _KINDS:
            if test(st.st_mode):
                raise OutputError(f"{where}: is {kind}, not a regular file; refusing to "
                                  f"replace it")
        if not stat.S_ISREG(st.st_mode):
            raise OutputError(f"{where}: not a regular file; refusing to replace it")
    parent = target.parent
    if not parent.exists():
        raise OutputError(f"{where}: directory {parent} does not exist (it is not created)")
    if not parent.is_dir():
        raise OutputError(f"{where}: {parent} is not a directory")
    return target


def check_directory(path: str | os.PathLike[str], flag: str = "--out") -> None:
    """Refuse (OutputError) an output directory :meth:`Outputs.directory` would refuse, without
    creating anything: a command checks it before long work and declares it at the end."""
    d = Path(path)
    where = f"{flag} {d}"
    if d.exists() or d.is_symlink():
        if not d.is_dir():
            raise OutputError(f"{where}: exists and is not a directory")
        _probe(d, f"{where}: cannot write in it")
        return
    parent = d.parent
    if not parent.exists():
        raise OutputError(f"{where}: directory {parent} does not exist (it is not created)")
    if not parent.is_dir():
        raise OutputError(f"{where}: {parent} is not a directory")
    _probe(parent, f"{where}: cannot create the directory")


def _probe(directory: Path, what: str) -> None:
    """Create and remove a temporary directory in ``directory`` (the permission bits do not
    tell, e.g. for root or on a read-only file system), or OutputError ``what: reason``."""
    try:
        os.rmdir(tempfile.mkdtemp(prefix=".probe.", dir=str(directory)))
    except OSError as exc:
        raise OutputError(f"{what}: {exc.strerror or exc}") from None


@dataclass
class _Pending:
    target: Path
    tmp: Path
    where: str


class Outputs:
    """All outputs of one command, committed together or not at all (see the module's
    docstring).  Use as a context manager::

        with Outputs() as outs:
            csv_tmp = outs.add(args.out, "--out")        # refused here if it cannot be written
            png_tmp = outs.add(args.plot, "--plot")
            ... long work; write to csv_tmp and png_tmp ...
            outs.commit()                                 # renames both into place

    Leaving the block without ``commit()`` (an exception, a refusal) removes every temporary
    file and any directory made by :meth:`directory`.
    """

    def __init__(self) -> None:
        self._pending: list[_Pending] = []
        self._made_dirs: list[Path] = []
        self._committed = False

    def __enter__(self) -> "Outputs":
        return self

    def __exit__(self, *exc: object) -> None:
        if not self._committed:
            self.abort()

    def directory(self, path: str | os.PathLike[str], flag: str = "--out") -> Path:
        """An output directory the command was asked for: created if absent (its parent must
        exist), removed again on abort if it was created here; never a file or device."""
        d = Path(path)
        where = f"{flag} {d}"
        if d.exists() or d.is_symlink():
            if not d.is_dir():
                raise OutputError(f"{where}: exists and is not a directory")
            return d
        check_directory(d, flag)
        try:
            d.mkdir()
        except OSError as exc:
            raise OutputError(f"{where}: cannot create the directory: "
                              f"{exc.strerror or exc}") from None
        self._made_dirs.append(d)
        return d

    def add(self, path: str | os.PathLike[str], flag: str = "--out") -> Path:
        """Declare an output; returns the temporary path to write it to (same suffix)."""
        target = resolve_output(path, flag)
        where = f"{flag} {path}" if flag else str(path)
        for p in self._pending:
            if p.target.resolve() == target.resolve():
                raise OutputError(f"{where}: the same file as {p.where}")
        try:
            fd, tmp = tempfile.mkstemp(prefix="." + target.name + ".", suffix=target.suffix,
                                       dir=str(target.parent))
        except OSError as exc:
            raise OutputError(f"{where}: cannot write in {target.parent}: "
                              f"{exc.strerror or exc}") from None
        os.close(fd)
        self._pending.append(_Pending(target, Path(tmp), where))
        return Path(tmp)

    def write_lines(self, tmp: Path, lines: Iterable[str]) -> None:
        """Text lines (each ended by a newline) to a temporary path returned by :meth:`add`."""
        with open(tmp, "w", encoding="utf-8", newline="") as fh:
            for line in lines:
                fh.write(line)
                fh.write("\n")

    def write_text(self, tmp: Path, text: str) -> None:
        """Text, exactly as given, to a temporary path returned by :meth:`add`."""
        with open(tmp, "w", encoding="utf-8", newline="") as fh:
            fh.write(text)

    def commit(self) -> None:
        """Give every output its mode and rename them all into place (or restore all)."""
        new_mode = 0o666 & ~_umask()
        done: list[tuple[_Pending, Path | None]] = []
        try:
            for p in self._pending:
                backup: Path | None = None
                try:
                    st = os.stat(p.target)
                except FileNotFoundError:
                    st = None
                if st is not None:
                    if not stat.S_ISREG(st.st_mode):   # changed since it was declared
                        raise OutputError(f"{p.where}: no longer a regular file")
                    os.chmod(p.tmp, stat.S_IMODE(st.st_mode))
                    try:
                        os.chown(p.tmp, st.st_uid, st.st_gid)
                    except OSError:
                        pass                            # not permitted: keep ours
                    backup = p.tmp.with_name(p.tmp.name + ".old")
                    try:
                        os.link(p.target, backup)
                    except OSError:
                        backup = None                   # no hard links here: no restore
                else:
                    os.chmod(p.tmp, new_mode)
                with open(p.tmp, "rb") as fh:
                    os.fsync(fh.fileno())
                os.replace(p.tmp, p.target)
                done.append((p, backup))
        except BaseException as exc:     # put back what was replaced, then say why
            for p, backup in reversed(done):
                if backup is not None:
                    os.replace(backup, p.target)
                else:
                    os.unlink(p.target)
            self.abort()
            if isinstance(exc, OSError):
                raise OutputError(f"cannot commit the outputs: {exc.strerror or exc}") from None
            raise
        for _, backup in done:
            if backup is not None:
                os.unlink(backup)
        self._committed = True

    def abort(self) -> None:
        """Remove every temporary file and every directory made here (nothing is committed)."""
        for p in self._pending:
            for f in (p.tmp, p.tmp.with_name(p.tmp.name + ".old")):
                try:
                    os.unlink(f)
                except FileNotFoundError:
                    pass
        self._pending.clear()
        for d in reversed(self._made_dirs):
            try:
                os.rmdir(d)
            except OSError:
                pass
        self._made_dirs.clear()


def write_atomic(path: str | os.PathLike[str], lines: Iterable[str], flag: str = "") -> None:
    """One text file by the writer's rules (a command with one output)."""
    with Outputs() as outs:
        tmp = outs.add(path, flag)
        outs.write_lines(tmp, lines)
        outs.commit()
