#pragma once
// What the library throws. Every failure a caller can act on is an isotope::Error, whose what() is
// the message for the user; its kind tells a face what to answer (the command's exit code, the
// server's status, the Python exception):
//
//   OptionError             an option out of its range            exit 2, HTTP 400, ValueError
//   InvalidInput            an argument that is not what the call takes (a volume's dimensions,
//                           values that are not finite, a mesh's indices)   exit 1, HTTP 400, ValueError
//   IoError                 a file missing, unreadable, corrupt, or that cannot be written
//                                                                  exit 1, HTTP 500, OSError
//   TriangleBudgetTooSmall  no eps meets the triangle budget      exit 1, HTTP 400, RuntimeError
//   ExtractionCancelled     RunContext::cancel was set            the caller's own choice
//   DistributedError        a process of the group failed         its usage_error: exit 2, else 1
//
// Outside it: std::bad_alloc when memory runs out, and std::logic_error for a broken invariant of
// the library itself (a bug, never the input's fault).
#include <stdexcept>
#include <string>
#include <utility>

namespace isotope {

struct Error : std::runtime_error {
  using std::runtime_error::runtime_error;
};

// `option` is the option's name as the faces spell it ("eps", "max-triangles"; the command line
// adds "--"), `message` what it must be, e.g. "must be >= 0, got '-1'". what() is "OPTION MESSAGE".
struct OptionError : Error {
  OptionError(std::string option_name, std::string what_it_must_be)
      : Error(option_name + " " + what_it_must_be),
        option(std::move(option_name)),
        message(std::move(what_it_must_be)) {}
  std::string option, message;
};

struct InvalidInput : Error {
  using Error::Error;
};

// Names the file and what is wrong with it ("scan.isotope: brick 812 (band 0, brick 3 5 2):
// checksum mismatch"). A convert stopped by its RunContext::cancel throws IoError("interrupted").
struct IoError : Error {
  using Error::Error;
};

// Even the coarsest mesh the topology mode allows (eps = infinity) has more triangles than the
// budget; the message says how many.
struct TriangleBudgetTooSmall : Error {
  using Error::Error;
};

struct ExtractionCancelled : Error {
  ExtractionCancelled() : Error("extraction cancelled") {}
};

// What every process of a distributed call throws when one of them failed: the message is that
// process's own ("rank 1 of 3: scan.isotope: brick 812 (...): checksum mismatch"). `usage_error`
// is true when the failure was an option out of range (the command's exit code 2).
struct DistributedError : Error {
  DistributedError(int failed_rank, bool usage, const std::string& message)
      : Error(message), rank(failed_rank), usage_error(usage) {}
  int rank;
  bool usage_error;
};

}  // namespace isotope
