// SPDX-License-Identifier: MIT
#pragma once
// Every failure pdt reports is a pdt::Error. The operation that throws it has
// changed nothing: the triangulation (or engine, or file) is as it was before
// the call. what() says what was wrong and what to do about it. One exception:
// what a change hook throws (a pdt::Error its own refused call raised, say)
// leaves a sequential insert or remove after the change is made, which stays
// (changes.hpp).
#include <stdexcept>
#include <string>

namespace pdt {

enum class ErrorCode {
  non_finite_coordinate,  // NaN or infinite coordinate
  outside_domain,         // point outside the box an engine was declared with
  unknown_vertex,         // id never issued, already removed, or the infinite vertex
  bad_format,             // malformed input file (the message names file and line)
  io_failure,             // cannot open / read / write a file (disk full included)
  invalid_argument,       // any other argument out of its documented range
};

class Error : public std::runtime_error {
 public:
  Error(ErrorCode code, const std::string& message) : std::runtime_error(message), code_(code) {}
  ErrorCode code() const noexcept { return code_; }

 private:
  ErrorCode code_;
};

}  // namespace pdt
