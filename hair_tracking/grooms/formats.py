"""Which reader a groom file needs, by its name's extension, and reading it.

============  ==========================================  =====================================
extension     format                                      reader
============  ==========================================  =====================================
``.hair``     Cem Yuksel's hair files                     :mod:`~hair_tracking.grooms.cyhair`
``.data``     USC-HairSalon / Hair20k                     :mod:`~hair_tracking.grooms.counted`
``.bin``      CT2Hair                                     :mod:`~hair_tracking.grooms.counted`
``.ply``      polyline PLY (vertex + strand elements)     :mod:`~hair_tracking.grooms.ply`
``.npz``      numpy archive of strands                    :mod:`~hair_tracking.grooms.npz`
``.usd*``     USD BasisCurves (needs usd-core)            :mod:`~hair_tracking.grooms.usd`
============  ==========================================  =====================================
"""
import os

from hair_tracking.grooms.counted import read_ct2hair, read_data
from hair_tracking.grooms.cyhair import read_hair
from hair_tracking.grooms.npz import read_npz
from hair_tracking.grooms.ply import read_ply
from hair_tracking.grooms.polylines import GroomFileError, Polylines
from hair_tracking.grooms.usd import read_usd

READERS = {'.hair': read_hair, '.data': read_data, '.bin': read_ct2hair, '.ply': read_ply,
           '.npz': read_npz, '.usd': read_usd, '.usda': read_usd, '.usdc': read_usd,
           '.usdz': read_usd}


def read_strands(path: str) -> Polylines:
    """The strands of the groom file ``path``, read by the reader its extension names
    (GroomFileError for an unknown extension or a file that cannot be read)."""
    ext = os.path.splitext(path)[1].lower()
    reader = READERS.get(ext)
    if reader is None:
        raise GroomFileError(path, 'its name', f'one of the extensions {", ".join(READERS)}',
                             repr(ext) if ext else 'none')
    return reader(path)
