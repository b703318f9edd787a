#include "jobs/numbers.h"

#include <algorithm>
#include <cctype>
#include <charconv>
#include <cmath>
#include <cstdio>
#include <optional>

namespace scanpress {
namespace {

Status invalid(std::string_view what, const std::string& expected, std::string_view text) {
  std::string message(what);
  message += ": must be ";
  message += expected;
  message += ", got '";
  message += text;
  message += "'";
  return makeError(ErrorCode::kInvalidArgument, std::move(message));
}

std::string fmt(double x) {
  char buf[32];
  std::snprintf(buf, sizeof buf, "%g", x);
  return buf;
}

// A decimal written exactly: (negative ? -1 : 1) * digits * 10^exponent.
struct Decimal {
  bool negative = false;
  uint64_t digits = 0;
  int64_t exponent = 0;
};

// `[+-]D+[.D+][(e|E)[+-]D+]` over all of `text` (sign and exponent only where allowed); nullopt on anything
// else and on more significant digits than 64 bits hold (a value that large is out of every range here).
std::optional<Decimal> scanDecimal(std::string_view text, bool allow_sign, bool allow_exponent) {
  Decimal d;
  size_t i = 0;
  if (allow_sign && i < text.size() && (text[i] == '+' || text[i] == '-')) d.negative = text[i++] == '-';
  auto digits = [&](auto&& take) {
    const size_t first = i;
    for (; i < text.size() && std::isdigit(static_cast<unsigned char>(text[i])); ++i)
      if (!take(static_cast<uint64_t>(text[i] - '0'))) return false;
    return i > first;
  };
  auto mantissa = [&](uint64_t digit) {
    if (d.digits > (UINT64_MAX - digit) / 10) return false;
    d.digits = d.digits * 10 + digit;
    return true;
  };
  if (!digits(mantissa)) return std::nullopt;
  if (i < text.size() && text[i] == '.') {
    ++i;
    if (!digits([&](uint64_t digit) {
          --d.exponent;
          return mantissa(digit);
        }))
      return std::nullopt;
  }
  if (allow_exponent && i < text.size() && (text[i] == 'e' || text[i] == 'E')) {
    ++i;
    bool negative = false;
    if (i < text.size() && (text[i] == '+' || text[i] == '-')) negative = text[i++] == '-';
    int64_t e = 0;
    auto exponent = [&](uint64_t digit) {
      e = std::min<int64_t>(e * 10 + int64_t(digit), 100000);  // beyond every range already
      return true;
    };
    if (!digits(exponent)) return std::nullopt;
    d.exponent += negative ? -e : e;
  }
  if (i != text.size()) return std::nullopt;
  return d;
}

// The magnitude of `d` when it is a whole number that fits 64 bits.
std::optional<uint64_t> wholeMagnitude(const Decimal& d) {
  uint64_t v = d.digits;
  for (int64_t e = d.exponent; e < 0 && v != 0; ++e) {
    if (v % 10 != 0) return std::nullopt;
    v /= 10;
  }
  for (int64_t e = d.exponent; e > 0 && v != 0; --e) {
    if (v > UINT64_MAX / 10) return std::nullopt;
    v *= 10;
  }
  return v;
}

// log2 of a size unit: K, M, G, T in either case, optionally followed by `i` and/or `B`; `B` alone is bytes
// and no unit is MiB.
std::optional<int> unitShift(std::string unit) {
  for (char& c : unit) c = static_cast<char>(std::tolower(static_cast<unsigned char>(c)));
  if (unit.empty()) return 20;
  if (unit == "b") return 0;
  const size_t k = std::string_view("kmgt").find(unit[0]);
  const std::string rest = unit.substr(1);
  if (k == std::string_view::npos || !(rest.empty() || rest == "i" || rest == "b" || rest == "ib"))
    return std::nullopt;
  return 10 * static_cast<int>(k + 1);
}

template <typename T, typename Parse>
Result<std::vector<T>> parseList(std::string_view text, size_t count, std::string_view what, Parse parse) {
  std::vector<T> out;
  for (size_t i = 0;;) {
    const size_t comma = std::min(text.find(',', i), text.size());
    SP_ASSIGN_OR_RETURN(T x, parse(text.substr(i, comma - i)));
    out.push_back(x);
    if (comma == text.size()) break;
    i = comma + 1;
  }
  if (count > 0 && out.size() != count)
    return invalid(what, std::to_string(count) + " values separated by commas", text);
  return out;
}

}  // namespace

Result<int64_t> parseInteger(std::string_view text, int64_t lo, int64_t hi, std::string_view what) {
  const auto d = scanDecimal(text, true, true);
  const auto m = d ? wholeMagnitude(*d) : std::nullopt;
  const uint64_t limit = d && d->negative ? uint64_t(INT64_MAX) + 1 : uint64_t(INT64_MAX);
  if (m && *m <= limit) {
    const int64_t x = d->negative ? int64_t(0 - *m) : int64_t(*m);  // two's complement: -2^63 included
    if (x >= lo && x <= hi) return x;
  }
  return invalid(what, "an integer in [" + std::to_string(lo) + ", " + std::to_string(hi) + "]", text);
}

Result<uint64_t> parseUnsigned(std::string_view text, uint64_t hi, std::string_view what) {
  const auto d = scanDecimal(text, true, true);
  const auto m = d ? wholeMagnitude(*d) : std::nullopt;
  if (m && (!d->negative || *m == 0) && *m <= hi) return *m;
  const std::string range = hi == UINT64_MAX ? "below 2^64" : "in [0, " + std::to_string(hi) + "]";
  return invalid(what, "a non-negative integer " + range, text);
}

Result<double> parseNumber(std::string_view text, double lo, double hi, std::string_view what) {
  std::string_view t = text;
  if (t.starts_with('+') && !t.starts_with("+-")) t.remove_prefix(1);
  double x = 0;
  const auto [end, ec] = std::from_chars(t.data(), t.data() + t.size(), x);
  if (!t.empty() && ec == std::errc() && end == t.data() + t.size() && std::isfinite(x) && x >= lo && x <= hi)
    return x;
  return invalid(what, "a number in [" + fmt(lo) + ", " + fmt(hi) + "]", text);
}

Result<uint64_t> parseSize(std::string_view text, std::string_view what) {
  const size_t split = std::min(text.find_first_not_of("0123456789."), text.size());
  const auto shift = unitShift(std::string(text.substr(split)));
  if (const auto d = scanDecimal(text.substr(0, split), false, false); d && shift) {
    unsigned __int128 bytes = static_cast<unsigned __int128>(d->digits) << *shift;  // < 2^104
    for (int64_t e = d->exponent; e < 0; ++e) bytes /= 10;  // rounds down once: floor(floor(a/10)/10) = floor(a/100)
    if (bytes <= UINT64_MAX) return static_cast<uint64_t>(bytes);
  }
  return invalid(what, "a size below 2^64 bytes such as 512M, 2GiB or 1.5G (units K, M, G, T of 1024; no unit: MiB)",
                 text);
}

Result<std::vector<int64_t>> parseIntegerList(std::string_view text, int64_t lo, int64_t hi, size_t count,
                                              std::string_view what) {
  return parseList<int64_t>(text, count, what, [&](std::string_view t) { return parseInteger(t, lo, hi, what); });
}

Result<std::vector<double>> parseNumberList(std::string_view text, double lo, double hi, size_t count,
                                            std::string_view what) {
  return parseList<double>(text, count, what, [&](std::string_view t) { return parseNumber(t, lo, hi, what); });
}

std::string humanBytes(uint64_t bytes) {
  char b[32];
  if (bytes < 1000000) std::snprintf(b, sizeof b, "%.1f KB", bytes / 1e3);
  else if (bytes < 1000000000) std::snprintf(b, sizeof b, "%.1f MB", bytes / 1e6);
  else std::snprintf(b, sizeof b, "%.2f GB", bytes / 1e9);
  return b;
}

}  // namespace scanpress
