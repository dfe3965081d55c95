"""Imported grooms kept on disk: a groom file is read, placed on the head and its guides chosen
once (seconds for a full head of 100 k strands), then loaded (a fraction of a second).

An entry is named by the SHA-1 of the file's path, size, modification time and first and last
megabyte, every
``groom.*`` option and the package's sources (the folder is
:func:`hair_tracking.executable.cache_dir` ``grooms``: a new one after any edit of the code); a
changed file or option is a new entry.  At most :data:`ENTRIES` entries are kept, the oldest
used removed first.  Writing is atomic (a temporary name, then a rename) and best effort: a
folder that cannot be written means no cache, never an error; an entry that cannot be read is
rebuilt.
"""
import dataclasses
import hashlib
import os
from typing import Optional

import numpy as np

from hair_tracking.core.groom import Groom
from hair_tracking.core.scene import GroomSpec

#: Entries kept in the folder.
ENTRIES = 8
#: Bytes read from each end of a file for its entry's name.
SAMPLE_BYTES = 1 << 20


def folder() -> str:
    from hair_tracking.executable import cache_dir
    return cache_dir('grooms')


def key(spec: GroomSpec) -> Optional[str]:
    """The entry's name for ``spec`` (None when its file cannot be looked at)."""
    h = hashlib.sha1()
    try:
        st = os.stat(spec.file)
        with open(spec.file, 'rb') as f:           # and its ends, for a rewrite within a tick
            h.update(f.read(SAMPLE_BYTES))
            f.seek(max(0, st.st_size - SAMPLE_BYTES))
            h.update(f.read(SAMPLE_BYTES))
    except OSError:
        return None
    h.update(repr((os.path.realpath(spec.file), st.st_size, st.st_mtime_ns,
                   dataclasses.astuple(spec))).encode())
    return h.hexdigest()


def load(name: Optional[str]) -> Optional[Groom]:
    """The cached groom of the entry ``name`` (:func:`key`), or None."""
    path = os.path.join(folder(), f'{name}.npz') if name else ''
    if not path or not os.path.isfile(path):
        return None
    try:
        with np.load(path, allow_pickle=False) as z:
            ghosts = z['ghost_rest']
            groom = Groom(guide_rest=z['guide_rest'], ghost_rest=ghosts,
                          guide_index=z['guide_index'] if ghosts.shape[0] else None,
                          note=str(z['note']),
                          detail_rest=z['detail_rest'] if 'detail_rest' in z.files else None)
        os.utime(path)                            # used now: the last to be removed
    except (OSError, ValueError, KeyError):
        return None
    return groom


def store(name: Optional[str], groom: Groom) -> None:
    """Keep ``groom`` as the entry ``name`` (:func:`key`; nothing when it is None or the folder
    is not writable)."""
    if not name:
        return
    where = folder()
    tmp = os.path.join(where, f'.{name}.{os.getpid()}.partial.npz')
    try:
        os.makedirs(where, exist_ok=True)
        index = groom.guide_index if groom.guide_index is not None else np.zeros(0, np.int64)
        detail = {} if groom.detail_rest is None else {'detail_rest': groom.detail_rest}
        np.savez(tmp, guide_rest=groom.guide_rest, ghost_rest=groom.ghost_rest,
                 guide_index=index, note=np.str_(groom.note), **detail)
        os.replace(tmp, os.path.join(where, f'{name}.npz'))
        entries = sorted((e for e in os.scandir(where) if e.name.endswith('.npz') and
                          not e.name.startswith('.')), key=lambda e: e.stat().st_mtime_ns)
        for old in entries[:-ENTRIES]:
            os.unlink(old.path)
    except OSError:
        pass
    finally:
        if os.path.exists(tmp):
            os.unlink(tmp)
