"""isotope: multiresolution isosurface extraction with topology control, out of core, on all cores.

Three lines from a numpy array to a mesh:

    import isotope
    mesh = isotope.extract(volume, iso=64.5, eps=4)   # volume[z, y, x], or a file's path
    mesh.save("surface.glb")                          # .ply .obj .stl .glb .vtp

``mesh.vertices`` is (n, 3) float32 (x, y, z), ``mesh.faces`` (m, 3) uint32, ``mesh.normals``
(n, 3) float32 and ``mesh.stats`` a dict. A numpy array is indexed ``a[z, y, x]``, as numpy, HDF5
and scikit-image users expect; the mesh's columns are x, y, z, in physical coordinates
(``origin + spacing * index``, both given in x, y, z order). A float32 array in C order is read
where it is, without a copy, so it must not change while a call reads it (another thread writing
into it meanwhile gives a mesh of whatever was read); uint8, uint16, int16 and float64 are
converted once, and nested lists of numbers are read as float64.

The work runs with the GIL released; Ctrl-C stops it. Errors are raised with the words of the
command line: ``isotope.IoError`` (an OSError) for files, ``isotope.OptionError`` (a ValueError,
with ``.option``) for options out of range, ValueError for arrays that are not volumes (a spacing
or origin that is not finite, or a NaN, named by its x, y, z), RuntimeError for a Source used from
its own progress callback.
"""

import os
from numbers import Integral

import numpy as np

from . import _isotope
from ._isotope import IoError, Mesh, OptionError, __version__

__all__ = ["extract", "convert", "Source", "Store", "Mesh", "IoError", "OptionError", "__version__"]


def _option_error(name, message):
    error = OptionError(f"{name} {message}")
    error.option = name
    return error


def _extract_options(iso, eps, topology, error, weight, delta, focus, radius, max_triangles, eps_ties):
    """The options given (None: left out), by the names the command line spells; the library sets each
    from its value and refuses it in the command's words."""
    given = {"iso": iso, "eps": eps, "topology": topology, "error": error, "weight": weight, "delta": delta,
             "focus": focus, "radius": radius, "max-triangles": max_triangles, "eps-ties": eps_ties}
    return [(name, value) for name, value in given.items() if value is not None]


def _input(volume):
    if isinstance(volume, np.ndarray):
        return volume
    if isinstance(volume, (str, os.PathLike)):
        return os.fspath(volume)
    if isinstance(volume, (list, tuple)):  # nested lists of numbers: their values, as float64
        return np.asarray(volume, dtype=np.float64)
    return np.asarray(volume)  # an h5py dataset, a zarr array


def _triple(name, value, kind):
    if value is None:
        return None
    value = tuple(value)
    if len(value) != 3:
        raise _option_error(name, f"must have three values (x, y, z), got {len(value)}")
    if kind is int:  # as the command's --dims: "XxYxZ", read by the library's own parser
        return "x".join(_integer_text(v) for v in value)
    return tuple(float(v) for v in value)  # checked by the library with the volume


def _integer_text(value):
    """An integer as text, for the library's parsers to take or refuse in their own words."""
    if isinstance(value, Integral) and not isinstance(value, bool):
        return str(int(value))
    return repr(value)


def _integer(name, value):
    """An integer option for the library, which checks its range: one beyond 64 bits is passed as
    the nearest that fits, out of range too, so that the library refuses it in its own words."""
    if not isinstance(value, Integral) or isinstance(value, bool):
        raise _option_error(name, f"must be an integer, got {value!r}")
    return max(-(1 << 62), min(int(value), 1 << 62))


class Source:
    """An input opened once and extracted from as often as needed.

    ``input`` is a store made by :func:`convert` (read out of core: only the bricks an extraction
    reaches, through a cache of ``cache_mb``), a volume file (raw ``NAME_XxYxZ_TYPE.raw`` or any
    raw with ``dims=(x, y, z)`` and ``type``, ``FILE.h5:/dataset``, NRRD, a TIFF stack) or a numpy
    array ``a[z, y, x]``. A raw, HDF5 or TIFF file is streamed at eps 0, a window of layers at a
    time, so a file larger than memory extracts at full resolution. An array or NRRD is held in
    memory. The first extraction that needs a hierarchy (eps > 0, a triangle budget) converts the
    volume into a store of its own in the temporary directory (unlinked once opened) and pages it
    through a cache of ``cache_mb``, reporting to ``progress(fraction)``; only where that directory
    cannot take the store is the hierarchy built in memory (the volume read whole, 16 bytes a node).
    """

    def __init__(self, input, *, dims=None, type=None, spacing=None, origin=None, cache_mb=_isotope.DEFAULT_CACHE_MB,
                 progress=None):
        self._source = _isotope.Source(_input(input), _triple("dims", dims, int), type,
                                       _triple("spacing", spacing, float), _triple("origin", origin, float),
                                       _integer("cache-mb", cache_mb), progress)

    @property
    def info(self):
        """What the input is (dims in x, y, z; shape as numpy indexes it) and what was read so far.

        ``critical_paper`` and ``critical_exact`` (per cube, octahedron, diamond) are None until
        counted (``critical_counted``): a store's always are; a volume's once a hierarchy with its
        records' topology is built (an extraction in mode ``"none"`` builds one without).
        """
        return self._source.info

    def extract(self, iso, *, eps=0, topology="preserve", error="bound", weight=None, delta=None, focus=None,
                radius=None, max_triangles=None, eps_ties=None, threads=0):
        """The isosurface at ``iso`` (inside means value > iso), as a :class:`Mesh`.

        ``eps`` (data units) is the coarse surface's error bound (0, the default: full resolution,
        marching tetrahedra on every cell). ``topology``: ``"preserve"`` (the exact rule: components and
        Euler characteristic of eps = 0 kept), ``"simplify"`` (features of weight below ``delta``
        may go; ``weight`` = interval, gradient or size), ``"paper"`` or ``"none"``. ``focus`` =
        (x, y, z) and ``radius``: full resolution at the point, eps from radius on.
        ``max_triangles`` (at least 1; instead of an ``eps`` other than 0): the finest eps whose mesh fits,
        or on volumes over 257 a side one whose mesh holds 90-100% of it, chosen from a sample
        (``stats["budget_sampled"]``; with
        simplify and no delta, delta too; ``stats["chosen_eps_ties"]`` is the ``eps_ties`` that, with
        ``eps=stats["chosen_eps"]``, gives the same mesh). The same budget asked for again of this
        Source is the choice made the first time, without the search (``stats["budget_remembered"]``).
        ``eps_ties`` (with an ``eps``, 0 included):
        of the diamonds whose error equals eps exactly, refine only those of the N coarsest tie
        classes. ``threads``: 0 for all cores (up to 4096); a limit holds for the whole process while the call
        runs (oneTBB's), so concurrent calls share it.
        """
        options = _extract_options(iso, eps, topology, error, weight, delta, focus, radius, max_triangles, eps_ties)
        return self._source.extract(options, _integer_text(threads))


# The name Source had before it matched the C++ API's; kept so that code written against it runs.
Store = Source


def extract(volume, iso, *, eps=0, topology="preserve", error="bound", weight=None, delta=None, focus=None,
            radius=None, max_triangles=None, eps_ties=None, dims=None, type=None, spacing=None, origin=None,
            cache_mb=_isotope.DEFAULT_CACHE_MB, threads=0, progress=None):
    """One extraction: ``Source(volume, ...).extract(iso, ...)``; see :class:`Source`."""
    store = Source(volume, dims=dims, type=type, spacing=spacing, origin=origin, cache_mb=cache_mb, progress=progress)
    return store.extract(iso, eps=eps, topology=topology, error=error, weight=weight, delta=delta, focus=focus,
                         radius=radius, max_triangles=max_triangles, eps_ties=eps_ties, threads=threads)


def convert(volume, output, *, dims=None, type=None, spacing=None, origin=None, memory_mb=_isotope.DEFAULT_MEMORY_MB,
            zstd_level=_isotope.DEFAULT_ZSTD_LEVEL, brick_bits=_isotope.DEFAULT_BRICK_BITS, quantize_bits=0, threads=0,
            progress=None):
    """A volume (a file, as :class:`Source` takes, or an array) into a store at ``output``.

    The store holds the hierarchy in compressed, checksummed bricks, so that later extractions
    read only what they reach. ``memory_mb`` bounds the conversion's memory whatever the volume's
    size; ``quantize_bits`` 8 or 16 stores float values as codes (the error bound grows by half a
    code step). Written atomically. Returns what it measured (a dict).
    """
    return _isotope.convert(_input(volume), os.fspath(output), _triple("dims", dims, int), type,
                            _triple("spacing", spacing, float), _triple("origin", origin, float),
                            _integer("memory-mb", memory_mb), _integer("zstd-level", zstd_level),
                            _integer("brick-bits", brick_bits), _integer("quantize", quantize_bits),
                            _integer_text(threads), progress)
