// The Python module `scanpress`: a container into numpy arrays (the whole scan, some tiles, a box, a level), its
// tiles and levels, and arrays encoded into a container. Errors raise: ValueError for bad arguments and data
// (the message is scanpress's own, naming the file and the place), OSError for files that cannot be read or written.
//
// Encoding goes through a temporary PLY next to the output (jobs/mesh_io writes it, encodeFile reads it back, as the
// CLI would): the pipeline streams from files, and the arrays take that form for the cost of one write and read.
#include <pybind11/numpy.h>
#include <pybind11/pybind11.h>
#include <pybind11/stl.h>
#include <unistd.h>

#include <array>
#include <cstring>
#include <filesystem>
#include <optional>
#include <string>
#include <vector>

#include "jobs/commands.h"
#include "jobs/container_file.h"
#include "jobs/mesh_io/mesh_writer.h"
#include "jobs/mesh_io/texcoords.h"
#include "jobs/pipeline.h"
#include "jobs/report.h"

namespace py = pybind11;
using namespace scanpress;

namespace {

[[noreturn]] void raise(const Status& s) {
  if (s.code() == ErrorCode::kIo) {
    PyErr_SetString(PyExc_OSError, s.toString().c_str());
    throw py::error_already_set();
  }
  throw py::value_error(s.toString());
}

template <typename T>
T unwrap(Result<T> r) {
  if (!r.isOk()) raise(r.status());
  return std::move(r).value();
}

// One scalar channel's values as a numpy array of its type (the bit patterns as they are).
template <typename T>
py::array channelArray(const Mesh& m, size_t offset, size_t stride) {
  py::array_t<T> a(py::ssize_t(m.positions.size()));
  T* out = a.mutable_data();
  for (size_t i = 0; i < m.positions.size(); ++i) {
    const uint64_t bits = uint64_t(m.scalars[i * stride + offset]) |
                          (sizeof(T) == 8 ? uint64_t(m.scalars[i * stride + offset + 1]) << 32 : 0);
    std::memcpy(&out[i], &bits, sizeof(T));  // little-endian: the low bytes
  }
  return a;
}

py::dict meshDict(const Mesh& m) {
  py::dict d;
  // Scalar channels (a PLY's confidence, intensity, ...): name -> array of the channel's type.
  py::dict scalars;
  const size_t stride = scalarWords(m.scalar_channels);
  size_t offset = 0;
  for (const ScalarChannel& c : m.scalar_channels) {
    py::array a;
    switch (c.type) {
      case ScalarType::kInt8: a = channelArray<int8_t>(m, offset, stride); break;
      case ScalarType::kUint8: a = channelArray<uint8_t>(m, offset, stride); break;
      case ScalarType::kInt16: a = channelArray<int16_t>(m, offset, stride); break;
      case ScalarType::kUint16: a = channelArray<uint16_t>(m, offset, stride); break;
      case ScalarType::kInt32: a = channelArray<int32_t>(m, offset, stride); break;
      case ScalarType::kUint32: a = channelArray<uint32_t>(m, offset, stride); break;
      case ScalarType::kFloat32: a = channelArray<float>(m, offset, stride); break;
      case ScalarType::kFloat64: a = channelArray<double>(m, offset, stride); break;
    }
    scalars[py::str(c.name)] = a;
    offset += size_t(scalarTypeWords(c.type));
  }
  d["scalars"] = scalars;
  py::array_t<double> pos({py::ssize_t(m.positions.size()), py::ssize_t(3)});
  std::memcpy(pos.mutable_data(), m.positions.data(), m.positions.size() * sizeof(Vec3d));
  py::array_t<uint32_t> faces({py::ssize_t(m.triangles.size()), py::ssize_t(3)});
  std::memcpy(faces.mutable_data(), m.triangles.data(), m.triangles.size() * sizeof(Triangle));
  d["positions"] = pos;
  d["faces"] = faces;
  d["normals"] = py::none();
  d["colors"] = py::none();
  d["uvs"] = py::none();
  if (const auto tc = findTexcoords(m.scalar_channels)) {  // also in `scalars`, by their names
    py::array_t<double> uv({py::ssize_t(m.positions.size()), py::ssize_t(2)});
    double* out = uv.mutable_data();
    for (size_t i = 0; i < m.positions.size(); ++i) {
      const uint32_t* words = m.scalars.data() + i * stride;
      out[2 * i] = floatChannelValue(m.scalar_channels[tc->u], words + tc->u_word);
      out[2 * i + 1] = floatChannelValue(m.scalar_channels[tc->v], words + tc->v_word);
    }
    d["uvs"] = uv;
  }
  if (!m.normals.empty()) {
    py::array_t<float> n({py::ssize_t(m.normals.size()), py::ssize_t(3)});
    std::memcpy(n.mutable_data(), m.normals.data(), m.normals.size() * sizeof(m.normals[0]));
    d["normals"] = n;
  }
  if (!m.colors.empty()) {
    const int ch = m.color_channels == 4 ? 4 : 3;
    py::array_t<uint8_t> c({py::ssize_t(m.colors.size()), py::ssize_t(ch)});
    uint8_t* out = c.mutable_data();
    for (size_t i = 0; i < m.colors.size(); ++i)
      for (int k = 0; k < ch; ++k) out[i * ch + k] = m.colors[i][k];
    d["colors"] = c;
  }
  return d;
}

py::dict readContainer(const std::string& path, std::optional<std::vector<uint32_t>> tiles,
                       std::optional<uint32_t> level, std::optional<std::array<double, 6>> box, bool crop) {
  DecodeSettings s;
  s.input = path;
  s.tiles = std::move(tiles);
  s.level = level;
  s.box = box;
  s.crop = crop;
  DecodedMesh d;
  {
    py::gil_scoped_release release;
    auto r = decodeToMesh(s);
    if (!r.isOk()) {
      py::gil_scoped_acquire acquire;
      raise(r.status());
    }
    d = std::move(r).value();
  }
  py::dict out = meshDict(d.mesh);
  out["tiles"] = d.result.tiles;
  out["level"] = d.result.level ? py::cast(*d.result.level) : py::none();
  return out;
}

// The container's description, as `scanpress info --json` prints it (tiles with their world bounds and levels).
py::object info(const std::string& path) {
  ContainerFile f = unwrap(ContainerFile::open(path));
  return py::module_::import("json").attr("loads")(containerInfoJson(f));
}

py::dict encode(const std::string& output, py::array_t<double, py::array::c_style | py::array::forcecast> positions,
                py::object faces_obj, py::object normals_obj, py::object colors_obj, const std::string& codec,
                int bits, std::optional<double> max_error, const std::string& error, int threads) {
  if (positions.ndim() != 2 || positions.shape(1) != 3) throw py::value_error("positions must have shape (N, 3)");
  Mesh m;
  const size_t n = positions.shape(0);
  m.positions.resize(n);
  std::memcpy(m.positions.data(), positions.data(), n * sizeof(Vec3d));
  if (!faces_obj.is_none()) {
    auto faces = faces_obj.cast<py::array_t<int64_t, py::array::c_style | py::array::forcecast>>();
    if (faces.ndim() != 2 || faces.shape(1) != 3) throw py::value_error("faces must have shape (M, 3)");
    const int64_t* f = faces.data();
    for (py::ssize_t i = 0; i < faces.shape(0); ++i) {
      Triangle t;
      for (int k = 0; k < 3; ++k) {
        const int64_t v = f[3 * i + k];
        if (v < 0 || uint64_t(v) >= n)
          throw py::value_error("faces[" + std::to_string(i) + "] names vertex " + std::to_string(v) +
                                ", not in [0, " + std::to_string(n) + ")");
        t[k] = uint32_t(v);
      }
      m.triangles.push_back(t);
    }
  }
  if (!normals_obj.is_none()) {
    auto nr = normals_obj.cast<py::array_t<float, py::array::c_style | py::array::forcecast>>();
    if (nr.ndim() != 2 || nr.shape(1) != 3 || size_t(nr.shape(0)) != n)
      throw py::value_error("normals must have shape (N, 3) like positions");
    m.normals.resize(n);
    std::memcpy(m.normals.data(), nr.data(), n * sizeof(m.normals[0]));
  }
  if (!colors_obj.is_none()) {
    auto c = colors_obj.cast<py::array_t<uint8_t, py::array::c_style | py::array::forcecast>>();
    if (c.ndim() != 2 || (c.shape(1) != 3 && c.shape(1) != 4) || size_t(c.shape(0)) != n)
      throw py::value_error("colors must have shape (N, 3) or (N, 4) of uint8 like positions");
    const int ch = int(c.shape(1));
    m.color_channels = ch;
    m.colors.resize(n);
    for (size_t i = 0; i < n; ++i)
      for (int k = 0; k < 4; ++k) m.colors[i][k] = k < ch ? c.data()[i * ch + k] : 255;
  }
  namespace fs = std::filesystem;
  const fs::path out(output);
  const fs::path ply = (out.has_parent_path() ? out.parent_path() : fs::path(".")) /
                       ("." + out.filename().string() + ".input-" + std::to_string(::getpid()) + ".ply");
  EncodeSettings s;
  s.input = ply.string();
  s.output = output;
  s.codec = codec;
  s.bits = bits;
  s.threads = threads;
  if (max_error) {
    s.target.kind = TargetKind::kMaxError;
    s.target.max_error = *max_error;
    if (error != "rms" && error != "max") throw py::value_error("error must be 'rms' or 'max', got '" + error + "'");
    s.target.metric = error == "max" ? ErrorMetric::kMax : ErrorMetric::kRms;
  }
  if (!knownCodecName(codec))
    throw py::value_error("unknown codec '" + codec + "' (available: " + codecNames() + ", auto)");
  Result<EncodeResult> r = makeError(ErrorCode::kInternal, "not run");
  {
    py::gil_scoped_release release;
    Status w = writePly(s.input, m);
    r = w.isOk() ? encodeFile(s) : Result<EncodeResult>(w);
    std::error_code ec;
    fs::remove(ply, ec);
  }
  EncodeResult res = unwrap(std::move(r));
  if (res.target && !res.target->status.isOk()) raise(res.target->status);
  py::dict d;
  d["bytes"] = res.bytes;
  d["vertices"] = res.vertices;
  d["faces"] = res.faces;
  d["tiles"] = res.tiles.size();
  d["bits"] = res.grid.bits;
  d["codec"] = res.codec;
  d["bpv"] = res.bitsPerVertex();
  return d;
}

}  // namespace

PYBIND11_MODULE(scanpress, m) {
  m.doc() = "scanpress containers (.spz) as numpy arrays: read (whole, tiles, box, level), info, encode";
  m.attr("__version__") = SCANPRESS_VERSION;
  m.def("read", &readContainer, py::arg("path"), py::kw_only(), py::arg("tiles") = py::none(),
        py::arg("level") = py::none(), py::arg("box") = py::none(), py::arg("crop") = false,
        "Decodes a container into a dict of numpy arrays: positions (N, 3) float64, faces (M, 3) uint32, normals "
        "(N, 3) float32 or None, colors (N, 3|4) uint8 or None, uvs (N, 2) float64 or None, scalars a dict of (N,) arrays by name at their type; `tiles` a list of tile ids, `box` "
        "(xmin, ymin, zmin, xmax, ymax, zmax) in world units (`crop` keeps only the triangles inside), `level` a "
        "progressive codec's level.");
  m.def("info", &info, py::arg("path"),
        "The container's description as `scanpress info --json` gives it: grid, counts, tiles with world bounds "
        "and, for progressive codecs, their levels.");
  m.def("encode", &encode, py::arg("output"), py::arg("positions"), py::arg("faces") = py::none(), py::kw_only(),
        py::arg("normals") = py::none(), py::arg("colors") = py::none(), py::arg("codec") = "edgebreaker",
        py::arg("bits") = 16, py::arg("max_error") = py::none(), py::arg("error") = "rms", py::arg("threads") = 0,
        "Encodes arrays into a container at `output`: positions (N, 3), faces (M, 3) or None for a point cloud, "
        "optional normals and colors; `max_error` an error target relative to the diagonal (metric `error`, "
        "'rms' or 'max'). Returns bytes, vertices, faces, tiles, bits, codec and bpv.");
}
