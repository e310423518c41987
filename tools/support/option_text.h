#pragma once
// The extraction's options as the faces take them, by name: from text as a user types it (the
// command line, `isotope sweep`, `isotope serve`'s query) or as typed values (the Python module's
// numbers). Each option's words live here once, so that a value one face refuses every face
// refuses in the same words (docs/DESIGN.md, "Seams"); the library checks the ranges again
// (ExtractOptions::validate, RunContext::validate) for a host program that sets the fields itself.
#include <array>
#include <cstddef>
#include <cstdint>
#include <optional>
#include <set>
#include <string>
#include <string_view>
#include <utility>
#include <vector>

#include "isotope/extract.h"

namespace isotope {

// The longest option text any face reads: longer than any number or point a user types. Longer
// text "is too long" (parse_extract_options, and the Python module's text values).
inline constexpr size_t kMaxOptionTextChars = 128;

// A real number as a user types it: "0.25", "-3e-2", "+1" or a fraction "1/64"; nullopt otherwise.
std::optional<double> parse_real(std::string_view text);

// One option into OPTIONS, without the rules that relate options to each other (finish_options):
// iso, eps, error, topology, weight, delta, focus ("X,Y,Z"), radius, max-triangles, eps-ties.
// Throws OptionError naming it (an unknown name under its own name, "is not an extraction option").
void set_extract_option(ExtractOptions& options, std::string_view name, std::string_view text);
// The same from a number (a real option: iso, eps, delta, radius; an integer one: max-triangles,
// eps-ties), refused in the words the text would be.
void set_extract_option(ExtractOptions& options, std::string_view name, double value);
void set_extract_option(ExtractOptions& options, std::string_view name, int64_t value);
void set_extract_focus(ExtractOptions& options, const std::array<double, 3>& point);

// The rules between the options GIVEN (their names): iso required, delta and weight with simplify
// only, focus and radius together; a budget in simplify mode without a delta chooses delta too
// (auto_delta); then validate().
void finish_extract_options(ExtractOptions& options, const std::set<std::string>& given);

// Text options by name, each at most once: set_extract_option, then finish_extract_options.
ExtractOptions parse_extract_options(const std::vector<std::pair<std::string, std::string>>& given);

// A thread count as a user types it (RunContext::threads), refused in RunContext::validate's words.
int parse_thread_count(std::string_view text);

}  // namespace isotope
