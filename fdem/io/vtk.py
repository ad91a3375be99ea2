"""VTU + PVD series for ParaView: triangles and crack elements of every output frame.

* :func:`write_vtu` writes an unstructured grid as VTK XML with *raw appended binary* data
  (no base64: one ``tobytes`` per array, fast for 1e5..1e6 cells), optionally compressed
  block-wise with zlib or lzma in VTK's ``vtkZLibDataCompressor`` / ``vtkLZMADataCompressor``
  format, and optionally restricted to a selection of fields; ParaView, VTK/pyvista and meshio
  read it (sizes and times in ``docs/outputs.md``).
* :class:`PvdSeries` numbers the ``.vtu`` files of a time series and rewrites the ``.pvd``
  collection after every frame, so a run that stops early still leaves a valid series.

The history table is :mod:`fdem.io.history`, state files :mod:`fdem.io.npz`, pictures
:mod:`fdem.io.pictures`.
"""
from __future__ import annotations

import lzma
import os
import re
import zlib
from pathlib import Path
from xml.sax.saxutils import quoteattr
import numpy as np

__all__ = ["VTK_LINE", "VTK_TRIANGLE", "COMPRESSORS", "BLOCK_SIZE", "PRECISIONS", "write_vtu", "PvdSeries",
           "read_pvd"]


VTK_LINE = 3


VTK_TRIANGLE = 5


_VTK_TYPE = {
    np.dtype(np.float64): "Float64", np.dtype(np.float32): "Float32",
    np.dtype(np.int64): "Int64", np.dtype(np.int32): "Int32", np.dtype(np.uint8): "UInt8",
    np.dtype(np.int8): "Int8", np.dtype(np.uint32): "UInt32", np.dtype(np.uint64): "UInt64",
}


PRECISIONS = (None, "float32", "float64")
"""``precision`` values of :func:`write_vtu`: None writes floating arrays as given; ``"float32"``
or ``"float64"`` writes the points and every floating array in that type."""


def _as_vtk_array(a, precision: str | None = None) -> np.ndarray:
    a = np.asarray(a)
    if a.dtype == np.bool_:
        a = a.astype(np.uint8)
    if a.dtype not in _VTK_TYPE:
        a = a.astype(np.float64)
    if precision is not None and a.dtype.kind == "f":
        a = a.astype(precision, copy=False)
    return np.ascontiguousarray(a)


def _index_array(a: np.ndarray) -> np.ndarray:
    """Connectivity and offsets as Int32 when every value fits (half the bytes of Int64; VTK's
    XML readers, meshio and pyvista read either), else Int64."""
    a = np.asarray(a, dtype=np.int64)
    if a.size == 0 or (a.min() >= 0 and a.max() < 2 ** 31):
        return a.astype(np.int32)
    return a


COMPRESSORS = {"zlib": "vtkZLibDataCompressor", "lzma": "vtkLZMADataCompressor"}
"""``compression`` values of :func:`write_vtu` and the VTK compressor each one names."""


BLOCK_SIZE = 1 << 15
"""Uncompressed bytes per compressed block [B], VTK's own writer's 32 KiB (any size reads): zlib
level 1 compressed a 26 MB float32 frame in 0.40 s in 32 KiB blocks against 0.63 s in 1 MiB
ones, to within 0.1 % of the same size (the smaller block stays in cache; ``docs/outputs.md``)."""


def _compress_threads() -> int:
    """Threads that compress blocks (zlib and lzma release the GIL): ``NUMBA_NUM_THREADS`` if set,
    so output obeys the same cap as the kernels, else the CPU count."""
    try:
        return max(1, int(os.environ.get("NUMBA_NUM_THREADS", "")))
    except ValueError:
        return max(1, os.cpu_count() or 1)


def _compressed_block(raw: bytes, compression: str | None, level: int) -> bytes:
    """One appended data block: ``UInt64 n`` + raw bytes, or VTK's compressed layout.

    Compressed layout (VTK XML file format, "Compressed data"): header of UInt64
    ``[n_blocks, block_size, last_block_size, c_1, ..., c_n_blocks]`` (``last_block_size`` the
    uncompressed size of a partial last block, 0 when it is full; ``c_k`` compressed sizes),
    followed by the ``n_blocks`` compressed blocks.
    """
    if compression is None:
        return np.uint64(len(raw)).tobytes() + raw
    view = memoryview(raw)
    n = len(raw)
    chunks = [view[i:i + BLOCK_SIZE] for i in range(0, n, BLOCK_SIZE)]
    if compression == "zlib":
        def pack(b):
            return zlib.compress(b, level)
    else:
        def pack(b):
            return lzma.compress(b, preset=level)
    threads = min(_compress_threads(), len(chunks))
    if threads > 1:
        from concurrent.futures import ThreadPoolExecutor

        with ThreadPoolExecutor(threads) as pool:
            packed = list(pool.map(pack, chunks))
    else:
        packed = [pack(b) for b in chunks]
    head = np.array([len(packed), BLOCK_SIZE, n % BLOCK_SIZE] + [len(b) for b in packed], dtype=np.uint64)
    return head.tobytes() + b"".join(packed)


def _select(data: dict | None, fields) -> dict:
    """The entries of ``data`` named in ``fields`` (all when ``fields`` is None)."""
    data = data or {}
    if fields is None:
        return data
    return {k: v for k, v in data.items() if k in fields}


def write_vtu(path: str | os.PathLike, points: np.ndarray, cells: np.ndarray, cell_type: int = VTK_TRIANGLE,
              point_data: dict | None = None, cell_data: dict | None = None, compression: str | None = None,
              level: int = 1, fields=None, precision: str | None = None) -> Path:
    """Write one unstructured grid of a single cell type to ``path`` (VTK XML, appended binary).

    ``points`` (n, 2) or (n, 3) [m]; ``cells`` (m, k) node ids; data arrays (n,) / (m,) scalars
    or (n, c) / (m, c) vectors and tensors. 2-vectors are padded to 3 components: VTK takes a
    vector attribute only with 3 (``vtkDataSetAttributes::SetVectors`` refuses 2), and
    ``vtkWarpVector`` (ParaView's Warp By Vector) reads 3 values per tuple whatever the array
    holds, so a 2-component displacement warps by garbage. Symmetric tensors go as 6 components
    ``[xx, yy, zz, xy, yz, xz]`` (VTK's order; ``vtkTensorGlyph`` draws the same glyph as from
    the full 9). Connectivity and offsets are Int32 when they fit.

    ``precision``: None writes floating arrays as given (float64 stays float64: the default, exact
    round trips); ``"float32"`` writes the points and every floating array as Float32 (half the
    bytes, 7 significant digits: enough to look at, never to restart from).

    ``compression``: None (raw, the default: fastest to write and to read, see
    ``docs/outputs.md``), ``"zlib"`` (``vtkZLibDataCompressor``) or ``"lzma"``
    (``vtkLZMADataCompressor``), block-wise in blocks of :data:`BLOCK_SIZE` bytes, compression
    ``level`` (zlib 0-9, lzma preset 0-9; 1 is the fast end). Compression is lossless: the
    arrays read back bit for bit.

    ``fields``: names of the point and cell arrays to write (an iterable of str); None writes
    all of them. Points and cells are always written. A name that is in neither ``point_data``
    nor ``cell_data`` is refused (a typo would otherwise silently drop a field).
    """
    if compression is not None and compression not in COMPRESSORS:
        raise ValueError(f"compression must be None or one of {sorted(COMPRESSORS)}, got {compression!r}")
    if precision not in PRECISIONS:
        raise ValueError(f"precision must be one of {PRECISIONS}, got {precision!r}")
    if fields is not None:
        fields = {fields} if isinstance(fields, str) else set(fields)
        known = set(point_data or {}) | set(cell_data or {})
        unknown = sorted(fields - known)
        if unknown:
            raise ValueError(f"fields {unknown} are not among the point/cell arrays {sorted(known)}")
    point_data = _select(point_data, fields)
    cell_data = _select(cell_data, fields)
    path = Path(path)
    pts = np.asarray(points, dtype=np.float64)
    if pts.shape[1] == 2:
        pts = np.column_stack([pts, np.zeros(len(pts))])
    cells = np.asarray(cells, dtype=np.int64)
    if cells.ndim != 2:
        cells = cells.reshape(-1, 2 if cell_type == VTK_LINE else 3)
    n_cells, k = cells.shape if cells.size else (0, 2 if cell_type == VTK_LINE else 3)
    blocks: list[bytes] = []

    def data_array(name: str, arr, index: bool = False) -> str:
        arr = _index_array(arr) if index else _as_vtk_array(arr, precision)
        if arr.ndim == 2 and arr.shape[1] == 2:
            arr = np.column_stack([arr, np.zeros(len(arr), arr.dtype)])
        comps = "" if arr.ndim == 1 else f'NumberOfComponents="{arr.shape[1]}" '
        blocks.append(_compressed_block(arr.tobytes(), compression, level))
        return (f'<DataArray type="{_VTK_TYPE[arr.dtype]}" Name={quoteattr(name)} '
                f'{comps}format="appended" offset="\x00{len(blocks) - 1}\x00"/>')

    compressor = f' compressor="{COMPRESSORS[compression]}"' if compression else ""
    xml = ['<?xml version="1.0"?>',
           f'<VTKFile type="UnstructuredGrid" version="1.0" byte_order="LittleEndian" header_type="UInt64"'
           f'{compressor}>',
           "<UnstructuredGrid>",
           f'<Piece NumberOfPoints="{len(pts)}" NumberOfCells="{n_cells}">']
    xml.append("<PointData>")
    for name, arr in point_data.items():
        xml.append(data_array(name, arr))
    xml.append("</PointData><CellData>")
    for name, arr in cell_data.items():
        xml.append(data_array(name, arr))
    xml.append("</CellData><Points>")
    xml.append(data_array("Points", pts))
    xml.append("</Points><Cells>")
    xml.append(data_array("connectivity", cells.ravel(), index=True))
    xml.append(data_array("offsets", np.arange(1, n_cells + 1, dtype=np.int64) * k, index=True))
    xml.append(data_array("types", np.full(n_cells, cell_type, dtype=np.uint8)))
    xml.append("</Cells></Piece></UnstructuredGrid>")
    xml.append('<AppendedData encoding="raw">')
    # The blocks go into the appended section in the reverse order of their tags (offsets may
    # come in any order). meshio reads the blocks in file order, finding each tag by its offset
    # and rewriting it to an offset of its own base64 text; in tag order a rewritten tag whose
    # new offset equals a later block's raw offset is found first, and the file reads wrong or
    # not at all (it happened to a 24-triangle frame: two 1,736-byte arrays, base64 length 4,632,
    # the next block's offset). In reverse order every tag not yet read comes before the
    # rewritten ones.
    offsets, at = [0] * len(blocks), 0
    for i in reversed(range(len(blocks))):
        offsets[i], at = at, at + len(blocks[i])
    head = re.sub("\x00([0-9]+)\x00", lambda m: str(offsets[int(m.group(1))]), "\n".join(xml)).encode() + b"\n_"
    tail = b"\n</AppendedData>\n</VTKFile>\n"
    path.parent.mkdir(parents=True, exist_ok=True)
    try:
        with open(path, "wb") as fh:
            fh.write(head)
            for b in reversed(blocks):
                fh.write(b)
            fh.write(tail)
    except BaseException:
        # a part of a frame reads as nothing, and on a full disk its bytes are what the run's
        # summary and checkpoint need: remove it
        path.unlink(missing_ok=True)
        raise
    return path


class PvdSeries:
    """A ParaView time series ``<directory>/<name>.pvd`` of ``<name>_<frame>.vtu`` files.

    ``compression``, ``level``, ``fields`` and ``precision`` are passed to :func:`write_vtu` for
    every frame.
    """

    def __init__(self, directory: str | os.PathLike, name: str, compression: str | None = None,
                 level: int = 1, fields=None, precision: str | None = None):
        if precision not in PRECISIONS:
            raise ValueError(f"precision must be one of {PRECISIONS}, got {precision!r}")
        self.directory = Path(directory)
        self.name = name
        self.compression, self.level, self.fields, self.precision = compression, level, fields, precision
        self.frames: list[tuple[float, str]] = []
        self.directory.mkdir(parents=True, exist_ok=True)

    @property
    def pvd_path(self) -> Path:
        return self.directory / f"{self.name}.pvd"

    def write(self, time: float, points, cells, cell_type: int = VTK_TRIANGLE,
              point_data: dict | None = None, cell_data: dict | None = None, filename: str | None = None) -> Path:
        """Write one frame at ``time`` [s] and rewrite the ``.pvd`` collection."""
        filename = filename or f"{self.name}_{len(self.frames):05d}.vtu"
        path = write_vtu(self.directory / filename, points, cells, cell_type, point_data, cell_data,
                         compression=self.compression, level=self.level, fields=self.fields,
                         precision=self.precision)
        self.frames.append((float(time), filename))
        self._write_pvd()
        return path

    def _write_pvd(self) -> None:
        lines = ['<?xml version="1.0"?>',
                 '<VTKFile type="Collection" version="0.1" byte_order="LittleEndian">', "<Collection>"]
        lines += [f'<DataSet timestep="{t:.17g}" group="" part="0" file={quoteattr(f)}/>' for t, f in self.frames]
        lines += ["</Collection>", "</VTKFile>", ""]
        tmp = self.pvd_path.with_suffix(".pvd.tmp")
        tmp.write_text("\n".join(lines))
        os.replace(tmp, self.pvd_path)


def read_pvd(path: str | os.PathLike) -> list[tuple[float, Path]]:
    """``(time, vtu path)`` of each frame of a ``.pvd`` collection."""
    import xml.etree.ElementTree as ET

    path = Path(path)
    root = ET.parse(path).getroot()
    return [(float(d.get("timestep")), path.parent / d.get("file")) for d in root.iter("DataSet")]
