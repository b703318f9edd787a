// Tiles encoded in other processes: see jobs/remote_tiles.h.
#include "jobs/remote_tiles.h"

#include <algorithm>
#include <cstring>
#include <map>
#include <type_traits>

#include "engine/io/bytes.h"
#include "engine/stages/stage.h"
#include "jobs/errors.h"
#include "spatial/surface_index.h"

namespace scanpress {

namespace {

// Bumped whenever a message's layout changes.
constexpr uint32_t kWireVersion = 8;  // 2: the layout's color bits; 3: the remesh stage's options; 4: prm's
// options; 5: scalar channels (the layout's, and each tile's values); 6: each scalar channel's bits; 7: each
// result's payload version; 8: its merged points

// The wire spells out every field of these structs: a new field must be added to the messages below too (this
// fails to compile until its size is updated here).
static_assert(sizeof(CodecOptions) == 56, "CodecOptions changed: update scanMessage and TileServer::scan");
static_assert(sizeof(StageSpec) == 48, "StageSpec changed: update scanMessage and TileServer::scan");
static_assert(sizeof(CodecLevel) == 48, "CodecLevel changed: update resultMessage, readResult and kLevelBytes");
// A level's bytes in a kResult message (resultMessage).
constexpr size_t kLevelBytes = 4 + 8 + 1 + 1 + 4 + 8 + 8 + 8;

TileTransport* g_transport = nullptr;

void putString(ByteWriter& w, const std::string& s) {
  w.varint(s.size());
  w.bytes({reinterpret_cast<const uint8_t*>(s.data()), s.size()});
}

Status getString(ByteReader& r, std::string& s) {
  uint64_t n = 0;
  SP_RETURN_IF_ERROR(r.varint(n));
  std::span<const uint8_t> b;
  SP_RETURN_IF_ERROR(r.bytes(n, b));
  s.assign(b.begin(), b.end());
  return Status::ok();
}

// A status as its code and message.
void putStatus(ByteWriter& w, const Status& status) {
  w.u8(static_cast<uint8_t>(status.code()));
  putString(w, status.message());
}

Status getStatus(ByteReader& r, Status& status) {
  uint8_t code = 0;
  std::string text;
  SP_RETURN_IF_ERROR(r.u8(code));
  SP_RETURN_IF_ERROR(getString(r, text));
  if (code > static_cast<uint8_t>(ErrorCode::kInternal)) return r.error(ErrorCode::kMalformed, "unknown error code");
  status = Status(static_cast<ErrorCode>(code), std::move(text));
  return Status::ok();
}

// An array of plain values, as its count and its bytes (both sides are the same little-endian build).
template <typename T>
void putArray(ByteWriter& w, const std::vector<T>& v) {
  static_assert(std::is_trivially_copyable_v<T>);
  w.varint(v.size());
  w.bytes({reinterpret_cast<const uint8_t*>(v.data()), v.size() * sizeof(T)});
}

template <typename T>
Status getArray(ByteReader& r, std::vector<T>& v) {
  uint64_t n = 0;
  SP_RETURN_IF_ERROR(r.varint(n));
  if (n > r.remaining() / sizeof(T))
    return r.error(ErrorCode::kMalformed, "an array of " + std::to_string(n) + " values does not fit the message");
  std::span<const uint8_t> b;
  SP_RETURN_IF_ERROR(r.bytes(n * sizeof(T), b));
  v.resize(n);
  if (n) std::memcpy(v.data(), b.data(), b.size());
  return Status::ok();
}

void putAccumulator(ByteWriter& w, const ErrorAccumulator& a) {
  w.u64(a.count);
  w.f64(a.sum);
  w.f64(a.sum_sq);
  w.f64(a.max);
}

Status getAccumulator(ByteReader& r, ErrorAccumulator& a) {
  SP_RETURN_IF_ERROR(r.u64(a.count));
  SP_RETURN_IF_ERROR(r.f64(a.sum));
  SP_RETURN_IF_ERROR(r.f64(a.sum_sq));
  return r.f64(a.max);
}

Status expectKind(ByteReader& r, TileMessage kind) {
  uint8_t k = 0;
  SP_RETURN_IF_ERROR(r.u8(k));
  if (k != static_cast<uint8_t>(kind)) return r.error(ErrorCode::kMalformed, "unexpected message kind");
  return Status::ok();
}

Status expectEnd(const ByteReader& r) {
  if (r.remaining()) return r.error(ErrorCode::kMalformed, std::to_string(r.remaining()) + " bytes too many");
  return Status::ok();
}

Status toBool(ByteReader& r, bool& b) {
  uint8_t v = 0;
  SP_RETURN_IF_ERROR(r.u8(v));
  if (v > 1) return r.error(ErrorCode::kMalformed, "a flag is not 0 or 1");
  b = v;
  return Status::ok();
}

// The settings and facts of a kScan message.
Status readScan(std::span<const uint8_t> message, EncodeSettings& s, TileScanFacts& f) {
  ByteReader r(message, "scan message");
  SP_RETURN_IF_ERROR(expectKind(r, TileMessage::kScan));
  uint32_t version = 0;
  SP_RETURN_IF_ERROR(r.u32(version));
  if (version != kWireVersion)
    return r.error(ErrorCode::kUnknownVersion, "wire version " + std::to_string(version) + ", this worker speaks " +
                                                   std::to_string(kWireVersion) + " (run one build on every rank)");
  SP_RETURN_IF_ERROR(getString(r, s.codec));
  uint64_t stages = 0;
  SP_RETURN_IF_ERROR(r.varint(stages));
  if (stages > 64) return r.error(ErrorCode::kMalformed, "too many stages");
  s.stages.assign(stages, StageSpec{});
  for (StageSpec& st : s.stages) {
    uint8_t kind = 0;
    uint32_t iterations = 0;
    SP_RETURN_IF_ERROR(r.u8(kind));
    st.kind = static_cast<StageKind>(kind);
    SP_RETURN_IF_ERROR(r.u32(iterations));
    st.smooth.iterations = static_cast<int>(iterations);
    SP_RETURN_IF_ERROR(r.f64(st.smooth.lambda));
    SP_RETURN_IF_ERROR(r.f64(st.smooth.mu));
    SP_RETURN_IF_ERROR(r.f64(st.remesh.grid));
    SP_RETURN_IF_ERROR(r.f64(st.remesh.tau));
  }
  uint8_t weights = 0, metric = 0;
  SP_RETURN_IF_ERROR(toBool(r, s.codec_options.octree.contexts));
  SP_RETURN_IF_ERROR(r.u8(weights));
  s.codec_options.pm.weights = static_cast<SimplifyWeights>(weights);
  SP_RETURN_IF_ERROR(r.f64(s.codec_options.pm.max_error));
  SP_RETURN_IF_ERROR(r.f64(s.codec_options.pm.ratio));
  SP_RETURN_IF_ERROR(r.f64(s.codec_options.prm.grid));
  SP_RETURN_IF_ERROR(r.f64(s.codec_options.prm.tau));
  SP_RETURN_IF_ERROR(r.f64(s.codec_options.prm.spacing));
  MeasureSettings& m = s.measure;
  SP_RETURN_IF_ERROR(toBool(r, m.enabled));
  SP_RETURN_IF_ERROR(r.f64(m.samples_per_triangle));
  SP_RETURN_IF_ERROR(r.u64(m.samples));
  SP_RETURN_IF_ERROR(r.u64(m.seed));
  SP_RETURN_IF_ERROR(toBool(r, m.stratified));
  SP_RETURN_IF_ERROR(toBool(r, m.vertices));
  SP_RETURN_IF_ERROR(r.f64(s.tile_error));
  SP_RETURN_IF_ERROR(r.u8(metric));
  s.tile_metric = metric ? ErrorMetric::kMax : ErrorMetric::kRms;
  SP_RETURN_IF_ERROR(r.f64(s.knob_cells));
  uint32_t threads = 0;
  SP_RETURN_IF_ERROR(r.u32(threads));
  s.threads = static_cast<int>(threads);
  for (int a = 0; a < 3; ++a) SP_RETURN_IF_ERROR(r.f64(f.grid.origin[a]));
  SP_RETURN_IF_ERROR(r.f64(f.grid.cell));
  uint8_t bits = 0;
  SP_RETURN_IF_ERROR(r.u8(bits));
  f.grid.bits = bits;
  SP_RETURN_IF_ERROR(r.u8(f.layout.normal_bits));
  SP_RETURN_IF_ERROR(r.u8(f.layout.color_channels));
  SP_RETURN_IF_ERROR(r.u8(f.layout.color_bits));
  uint8_t scalar_count = 0;
  SP_RETURN_IF_ERROR(r.u8(scalar_count));
  for (uint8_t i = 0; i < scalar_count; ++i) {
    uint8_t type = 0;
    SP_RETURN_IF_ERROR(r.u8(type));
    if (!validScalarType(type)) return r.error(ErrorCode::kMalformed, "scalar channel type out of range");
    ScalarChannel c;
    c.type = static_cast<ScalarType>(type);
    SP_RETURN_IF_ERROR(getString(r, c.name));
    if (!validScalarName(c.name)) return r.error(ErrorCode::kMalformed, "scalar channel name");
    SP_RETURN_IF_ERROR(r.u8(c.bits));
    if (c.bits > kMaxScalarBits || (c.bits && !isFloatScalar(c.type)))
      return r.error(ErrorCode::kMalformed, "scalar channel bits");
    f.layout.scalars.push_back(std::move(c));
  }
  SP_RETURN_IF_ERROR(toBool(r, f.measured));
  SP_RETURN_IF_ERROR(r.f64(f.diagonal));
  SP_RETURN_IF_ERROR(r.f64(f.density));
  if (f.grid.bits < kMinGridBits || f.grid.bits > kMaxGridBits)
    return r.error(ErrorCode::kMalformed, "grid bits out of range");
  if (f.layout.normal_bits != 0 && (f.layout.normal_bits < 4 || f.layout.normal_bits > 16))
    return r.error(ErrorCode::kMalformed, "normal bits out of range");
  if (f.layout.color_channels != 0 && f.layout.color_channels != 3 && f.layout.color_channels != 4)
    return r.error(ErrorCode::kMalformed, "color channels out of range");
  if (f.layout.color_bits < 1 || f.layout.color_bits > 8)
    return r.error(ErrorCode::kMalformed, "color bits out of range");
  return expectEnd(r);
}

}  // namespace

void setTileTransport(TileTransport* transport) { g_transport = transport; }
TileTransport* tileTransport() { return g_transport; }

std::vector<uint8_t> scanMessage(const EncodeSettings& s, const TileScanFacts& f) {
  std::vector<uint8_t> out;
  ByteWriter w(out);
  w.u8(static_cast<uint8_t>(TileMessage::kScan));
  w.u32(kWireVersion);
  putString(w, s.codec);
  w.varint(s.stages.size());
  for (const StageSpec& st : s.stages) {
    w.u8(static_cast<uint8_t>(st.kind));
    w.u32(static_cast<uint32_t>(st.smooth.iterations));
    w.f64(st.smooth.lambda);
    w.f64(st.smooth.mu);
    w.f64(st.remesh.grid);
    w.f64(st.remesh.tau);
  }
  w.u8(s.codec_options.octree.contexts);
  w.u8(static_cast<uint8_t>(s.codec_options.pm.weights));
  w.f64(s.codec_options.pm.max_error);
  w.f64(s.codec_options.pm.ratio);
  w.f64(s.codec_options.prm.grid);
  w.f64(s.codec_options.prm.tau);
  w.f64(s.codec_options.prm.spacing);
  const MeasureSettings& m = s.measure;  // the picture's settings stay on rank 0, which renders
  w.u8(m.enabled);
  w.f64(m.samples_per_triangle);
  w.u64(m.samples);
  w.u64(m.seed);
  w.u8(m.stratified);
  w.u8(m.vertices);
  w.f64(s.tile_error);
  w.u8(static_cast<uint8_t>(s.tile_metric));
  w.f64(s.knob_cells);
  w.u32(static_cast<uint32_t>(std::max(0, s.threads)));
  for (int a = 0; a < 3; ++a) w.f64(f.grid.origin[a]);
  w.f64(f.grid.cell);
  w.u8(static_cast<uint8_t>(f.grid.bits));
  w.u8(f.layout.normal_bits);
  w.u8(f.layout.color_channels);
  w.u8(f.layout.color_bits);
  w.u8(static_cast<uint8_t>(f.layout.scalars.size()));
  for (const ScalarChannel& c : f.layout.scalars) {
    w.u8(static_cast<uint8_t>(c.type));
    putString(w, c.name);
    w.u8(c.bits);
  }
  w.u8(f.measured);
  w.f64(f.diagonal);
  w.f64(f.density);
  return out;
}

std::vector<uint8_t> tileMessage(const TileMesh& tm, const std::vector<Vec3d>& originals) {
  std::vector<uint8_t> out;
  out.reserve(64 + tm.mesh.positions.size() * (12 + 4 + 4 + 1 + 24) + tm.mesh.triangles.size() * 12);
  ByteWriter w(out);
  w.u8(static_cast<uint8_t>(TileMessage::kTile));
  w.u32(tm.tile_id);
  putArray(w, tm.mesh.positions);
  putArray(w, tm.mesh.normals);
  putArray(w, tm.mesh.colors);
  putArray(w, tm.mesh.scalars);
  putArray(w, tm.mesh.triangles);
  putArray(w, tm.local_to_global);
  putArray(w, tm.border);
  putArray(w, originals);
  return out;
}

std::vector<uint8_t> quitMessage() { return {static_cast<uint8_t>(TileMessage::kQuit)}; }

std::vector<uint8_t> readyMessage(uint32_t slots, const Status& status) {
  std::vector<uint8_t> out;
  ByteWriter w(out);
  w.u8(static_cast<uint8_t>(TileMessage::kReady));
  w.u32(slots);
  putStatus(w, status);
  return out;
}

std::vector<uint8_t> resultMessage(const TileResult& t) {
  std::vector<uint8_t> out;
  out.reserve(128 + t.encoded.payload.size() + t.status.message().size());
  ByteWriter w(out);
  w.u8(static_cast<uint8_t>(TileMessage::kResult));
  w.u32(t.tile);
  putStatus(w, t.status);
  putArray(w, t.encoded.payload);
  w.u16(t.encoded.version);
  w.u64(t.encoded.merged_points);
  const TileSummary& d = t.encoded.decoded;
  w.u32(d.vertices);
  w.u32(d.faces);
  for (int a = 0; a < 3; ++a) w.u32(d.lo[a]);
  for (int a = 0; a < 3; ++a) w.u32(d.hi[a]);
  w.varint(t.encoded.levels.size());
  for (const CodecLevel& l : t.encoded.levels) {
    w.u32(l.level);
    w.u64(l.end_bytes);
    w.u8(static_cast<uint8_t>(l.kind));
    w.u8(l.complete);
    w.u32(l.cell_bits);
    w.u64(l.vertices);
    w.f64(l.max_error);
    w.f64(l.spacing);
  }
  w.u32(t.border);
  w.u32(t.input_vertices);
  w.u32(t.input_faces);
  putAccumulator(w, t.forward);
  putAccumulator(w, t.backward);
  w.f64(t.knob_cells);
  w.u8(t.target_met);
  w.u32(t.knob_trials);
  return out;
}

Result<TileMessage> messageKind(std::span<const uint8_t> message) {
  if (message.empty()) return makeError(ErrorCode::kMalformed, "tile message: empty");
  const uint8_t k = message[0];
  if (k < static_cast<uint8_t>(TileMessage::kScan) || k > static_cast<uint8_t>(TileMessage::kResult))
    return makeError(ErrorCode::kMalformed, "tile message: unknown kind " + std::to_string(k));
  return static_cast<TileMessage>(k);
}

Result<Ready> readReady(std::span<const uint8_t> message) {
  ByteReader r(message, "ready message");
  SP_RETURN_IF_ERROR(expectKind(r, TileMessage::kReady));
  Ready ready;
  SP_RETURN_IF_ERROR(r.u32(ready.slots));
  SP_RETURN_IF_ERROR(getStatus(r, ready.status));
  SP_RETURN_IF_ERROR(expectEnd(r));
  return ready;
}

Result<TileResult> readResult(std::span<const uint8_t> message) {
  ByteReader r(message, "result message");
  SP_RETURN_IF_ERROR(expectKind(r, TileMessage::kResult));
  TileResult t;
  SP_RETURN_IF_ERROR(r.u32(t.tile));
  SP_RETURN_IF_ERROR(getStatus(r, t.status));
  SP_RETURN_IF_ERROR(getArray(r, t.encoded.payload));
  SP_RETURN_IF_ERROR(r.u16(t.encoded.version));
  SP_RETURN_IF_ERROR(r.u64(t.encoded.merged_points));
  TileSummary& d = t.encoded.decoded;
  SP_RETURN_IF_ERROR(r.u32(d.vertices));
  SP_RETURN_IF_ERROR(r.u32(d.faces));
  for (int a = 0; a < 3; ++a) SP_RETURN_IF_ERROR(r.u32(d.lo[a]));
  for (int a = 0; a < 3; ++a) SP_RETURN_IF_ERROR(r.u32(d.hi[a]));
  uint64_t levels = 0;
  SP_RETURN_IF_ERROR(r.varint(levels));
  if (levels > r.remaining() / kLevelBytes) return r.error(ErrorCode::kMalformed, "too many levels for the message");
  t.encoded.levels.resize(levels);
  for (CodecLevel& l : t.encoded.levels) {
    uint8_t kind = 0;
    SP_RETURN_IF_ERROR(r.u32(l.level));
    SP_RETURN_IF_ERROR(r.u64(l.end_bytes));
    SP_RETURN_IF_ERROR(r.u8(kind));
    l.kind = static_cast<LevelKind>(kind);
    SP_RETURN_IF_ERROR(toBool(r, l.complete));
    SP_RETURN_IF_ERROR(r.u32(l.cell_bits));
    SP_RETURN_IF_ERROR(r.u64(l.vertices));
    SP_RETURN_IF_ERROR(r.f64(l.max_error));
    SP_RETURN_IF_ERROR(r.f64(l.spacing));
  }
  SP_RETURN_IF_ERROR(r.u32(t.border));
  SP_RETURN_IF_ERROR(r.u32(t.input_vertices));
  SP_RETURN_IF_ERROR(r.u32(t.input_faces));
  SP_RETURN_IF_ERROR(getAccumulator(r, t.forward));
  SP_RETURN_IF_ERROR(getAccumulator(r, t.backward));
  SP_RETURN_IF_ERROR(r.f64(t.knob_cells));
  SP_RETURN_IF_ERROR(toBool(r, t.target_met));
  SP_RETURN_IF_ERROR(r.u32(t.knob_trials));
  SP_RETURN_IF_ERROR(expectEnd(r));
  return t;
}

Status TileServer::scan(std::span<const uint8_t> message) {
  encoder_.reset();
  settings_ = EncodeSettings();
  TileScanFacts facts;
  Status status = readScan(message, settings_, facts);
  const CodecInfo* codec = status.isOk() ? findCodec(settings_.codec) : nullptr;
  if (status.isOk() && !codec)
    status = makeError(ErrorCode::kUnknownCodec, "worker: unknown codec " + settings_.codec);
  for (const StageSpec& st : settings_.stages)
    if (status.isOk() && !findStage(st.kind)) status = makeError(ErrorCode::kMalformed, "worker: unknown stage");
  std::shared_ptr<EmbreeDevice> device;
  if (status.isOk() && facts.measured) {
    auto created = EmbreeDevice::create();
    if (created.isOk()) device = *created;
    else status = created.status().withContext("worker");
  }
  facts_ = facts;
  if (status.isOk()) encoder_ = std::make_unique<TileEncoder>(settings_, *codec, facts, std::move(device), nullptr);
  scan_status_ = status.isOk() ? Status::ok() : status;
  return status;
}

std::vector<uint8_t> TileServer::tile(std::span<const uint8_t> message) const {
  TileResult failed;
  failed.tile = kUnreadTile;  // until the message's tile id is read: matches no tile rank 0 sent
  try {
    TileMesh tm;
    std::vector<Vec3d> originals;
    ByteReader r(message, "tile message");
    Status status = scan_status_;
    if (status.isOk()) status = expectKind(r, TileMessage::kTile);
    if (status.isOk()) status = r.u32(tm.tile_id);
    if (status.isOk()) failed.tile = tm.tile_id;
    if (status.isOk()) status = getArray(r, tm.mesh.positions);
    if (status.isOk()) status = getArray(r, tm.mesh.normals);
    if (status.isOk()) status = getArray(r, tm.mesh.colors);
    if (status.isOk()) status = getArray(r, tm.mesh.scalars);
    if (status.isOk()) status = getArray(r, tm.mesh.triangles);
    if (status.isOk()) status = getArray(r, tm.local_to_global);
    if (status.isOk()) status = getArray(r, tm.border);
    if (status.isOk()) status = getArray(r, originals);
    if (status.isOk()) status = expectEnd(r);
    // The tile as the codecs may assume it: attributes per vertex, indices in range, on the grid.
    const size_t n = tm.mesh.positions.size();
    if (status.isOk()) status = validateTile(TileContext{facts_.grid.bits, facts_.layout}, tm.mesh);
    if (status.isOk() && (tm.local_to_global.size() != n || tm.border.size() != n ||
                          (facts_.measured ? originals.size() != n : !originals.empty())))
      status = makeError(ErrorCode::kMalformed, "ids, border flags or originals do not match the vertex count");
    if (status.isOk()) return resultMessage(encoder_->run(tm, originals));
    failed.status = status.withContext("worker");
  } catch (...) {  // run() catches the tile's own failures; this is reading the message or the result's bytes
    failed.status = statusFromException().withContext("worker");
  }
  failed.encoded = EncodedTile{};
  return resultMessage(failed);
}

Status runRemoteTiles(TileTransport& transport, const EncodeSettings& settings, const TileScanFacts& scan,
                      uint32_t first, uint32_t step, uint32_t count, const BuildTileMessage& build,
                      const std::function<void(const TileResult&)>& write) {
  const uint32_t workers = transport.workers();
  if (workers == 0) return makeError(ErrorCode::kInternal, "remote tiles: no workers");
  const std::vector<uint8_t> scan_message = scanMessage(settings, scan);
  for (uint32_t w = 0; w < workers; ++w) SP_RETURN_IF_ERROR(transport.send(w, scan_message));
  // Every worker answers the scan before any tile is sent.
  std::vector<uint32_t> slots(workers, 0), busy(workers, 0);
  Status status;
  for (uint32_t answered = 0; answered < workers; ++answered) {
    SP_ASSIGN_OR_RETURN(TileTransport::Received got, transport.receive());
    auto ready = readReady(got.message);
    if (!ready.isOk() || got.worker >= workers) {
      status = ready.isOk() ? makeError(ErrorCode::kInternal, "remote tiles: a reply from an unknown worker")
                            : ready.status().withContext("worker " + std::to_string(got.worker));
    } else if (!ready->status.isOk()) {
      status = ready->status.withContext("worker " + std::to_string(got.worker));
    } else {
      slots[got.worker] = std::clamp<uint32_t>(ready->slots, 1, 1024);
    }
  }
  SP_RETURN_IF_ERROR(status);

  // Results wait here for the ones before them: at most `window` tiles past the next one to write.
  uint64_t total_slots = 0;
  for (uint32_t s : slots) total_slots += s;
  const uint64_t window = 4 * total_slots;
  auto seqOf = [&](uint32_t tile) -> uint64_t { return (tile - first) / step; };
  std::map<uint64_t, TileResult> waiting;
  std::map<uint64_t, TileResult> sent;  // by sequence number, while the result is due: the tile as built
  uint64_t written = 0;
  uint32_t next = first, outstanding = 0;
  auto flush = [&] {
    try {
      for (auto it = waiting.find(written); it != waiting.end(); it = waiting.find(written)) {
        write(it->second);
        waiting.erase(it);
        ++written;
      }
    } catch (...) {
      if (status.isOk()) status = statusFromException();
    }
  };
  while (true) {
    while (status.isOk() && next < count && seqOf(next) - written < window) {
      uint32_t w = 0;  // the worker with the most free slots
      for (uint32_t i = 1; i < workers; ++i)
        if (slots[i] - busy[i] > slots[w] - busy[w]) w = i;
      if (busy[w] >= slots[w]) break;
      std::vector<uint8_t> message;
      TileResult built;
      try {
        built = build(next, message);
      } catch (...) {  // out of memory building the message: stop sending, answer what is out
        status = statusFromException();
        break;
      }
      if (!built.status.isOk()) {
        waiting.emplace(seqOf(next), std::move(built));
      } else if (Status sent_ok = transport.send(w, std::move(message)); !sent_ok.isOk()) {
        status = sent_ok;
        break;
      } else {
        ++busy[w];
        ++outstanding;
        sent.emplace(seqOf(next), built);
      }
      next += step;
      flush();
    }
    if (outstanding == 0) break;  // everything sent is answered; nothing more to send (or an error stopped it)
    SP_ASSIGN_OR_RETURN(TileTransport::Received got, transport.receive());
    auto result = readResult(got.message);
    if (got.worker >= workers || busy[got.worker] == 0) {  // a protocol error: nothing sensible is left to do
      return makeError(ErrorCode::kInternal,
                       "remote tiles: a message from worker " + std::to_string(got.worker) + ", which had no tile");
    }
    --busy[got.worker];
    --outstanding;
    if (!result.isOk()) {
      if (status.isOk()) status = result.status().withContext("worker " + std::to_string(got.worker));
      continue;
    }
    const uint32_t tile = result->tile;
    const auto due = tile < first || tile >= count || (tile - first) % step ? sent.end() : sent.find(seqOf(tile));
    if (due == sent.end()) {
      if (status.isOk())
        status = makeError(ErrorCode::kInternal, "worker " + std::to_string(got.worker) + " answered tile " +
                                                     std::to_string(tile) + ", which it was not sent");
      continue;
    }
    result->input_vertices = due->second.input_vertices;
    result->input_faces = due->second.input_faces;
    result->border = due->second.border;
    sent.erase(due);
    waiting.emplace(seqOf(tile), std::move(*result));
    if (status.isOk()) flush();
  }
  return status;
}

}  // namespace scanpress
