// .npz input: an indexed triangle mesh given as NumPy arrays in one .npz
// archive (numpy.savez or savez_compressed), for scenes that already live in
// arrays (Python's outcore.pack writes these):
//
//   vertices   (V, 3) float32 or float64   positions (converted to float32)
//   triangles  (T, 3) int32, int64, uint32 or uint64   vertex indices, 0-based
//
// Other members are ignored; C and Fortran order are both read. Like an OBJ
// or PLY input it is an indexed mesh: geometry_id is the input's position,
// primitive_id the triangle's row; degenerate triangles are kept (and
// counted by pack). Everything is checked when the file is opened, errors
// naming the file, the member and the row ("scene.npz, member triangles: row
// 7: vertex index 9 out of range (4 vertices)"): a missing member, a wrong
// dtype or shape, an index out of range, a coordinate that is not finite in
// float32 or beyond the coordinate limit (coordinate_limits.h).
//
// Why held whole rather than streamed: numpy's format puts each array in one
// (possibly deflated) member, and triangles index vertices at random, so the
// archive is read and decoded once at open and the mesh (12 B a vertex and
// 12 B a triangle) held for the source's life: streaming it again is cheap.
// held_memory_bytes() reports it; `pack` reserves it within half of --mem-mb
// (HeldMemoryLimit), and a mesh that does not fit is refused before it is
// converted. While opening, the archive's bytes are held too (transiently).
//
// Thread-safety: open/decode are reentrant; a source is used by one thread
// at a time.
#pragma once

#include <memory>
#include <string>
#include <string_view>

#include "core/io/triangle_source.h"

namespace outcore {

// NOT_FOUND for a missing file; INVALID_ARGUMENT for anything but a regular
// file and for the problems above; RESOURCE_EXHAUSTED beyond `held`.
Expected<std::unique_ptr<TriangleSource>> open_npz_mesh_file(const std::string& path,
                                                             const HeldMemoryLimit& held = {});
// The same from the archive's bytes; `name` is used in errors and as the
// source's description.
Expected<std::unique_ptr<TriangleSource>> decode_npz_mesh(std::string_view bytes, const std::string& name,
                                                          const HeldMemoryLimit& held = {});

}  // namespace outcore
