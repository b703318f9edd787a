// Numbers typed by users, parsed one way for the command line and for job files (which pass a JSON number's
// text).
//
// Integers are decimal, with an optional sign, fraction and exponent as long as the value is a whole number:
// `42`, `+42`, `1e6`, `2.5e3` and `16.0` are integers; `1.5`, `0x10`, ` 4`, `4 `, `1_000` are not. Numbers
// (doubles) are decimal and finite: `inf`, `nan` and values beyond the double range (`1e400`) are errors.
// Sizes are a decimal number with an optional unit; units are binary multiples: K, M, G, T, in either case,
// optionally followed by `i` and/or `B` (`512M`, `512MB`, `2GiB`, `1.5G`, `64k`); `B` alone is bytes, and no
// unit is MiB. A fractional size rounds down to whole bytes.
//
// Every error is kInvalidArgument (exit 1) with the message `WHAT: must be ..., got 'TEXT'`, where `what`
// names the option (`--bits`) or the JSON pointer (`/codec/bits`).
#pragma once

#include <cstdint>
#include <string>
#include <string_view>
#include <vector>

#include "engine/status.h"

namespace scanpress {

Result<int64_t> parseInteger(std::string_view text, int64_t lo, int64_t hi, std::string_view what);
Result<uint64_t> parseUnsigned(std::string_view text, uint64_t hi, std::string_view what);
Result<double> parseNumber(std::string_view text, double lo, double hi, std::string_view what);
Result<uint64_t> parseSize(std::string_view text, std::string_view what);
// A byte count for people: "625.3 KB", "12.3 MB", "1.25 GB" (decimal units, as file managers show sizes).
std::string humanBytes(uint64_t bytes);

// Comma-separated values, each as parseInteger or parseNumber; `count` > 0 requires exactly that many.
Result<std::vector<int64_t>> parseIntegerList(std::string_view text, int64_t lo, int64_t hi, size_t count,
                                              std::string_view what);
Result<std::vector<double>> parseNumberList(std::string_view text, double lo, double hi, size_t count,
                                            std::string_view what);

}  // namespace scanpress
