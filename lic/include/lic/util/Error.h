// Typed exceptions of the lic library. Only the command line catches them.
#pragma once

#include <stdexcept>
#include <string>

namespace lic {

/// A runtime failure (I/O error, out of memory, cancelled): `licvdb` exits with 1.
class Error : public std::runtime_error
{
public:
    using std::runtime_error::runtime_error;
};

/// Bad input or bad usage (missing file, wrong grid type, NaN in a field, out-of-range
/// parameter): `licvdb` exits with 2. Messages name the bad value and what was expected.
class InputError : public Error
{
public:
    using Error::Error;
};

/// Thrown when an Interrupter asks a long operation to stop.
class Cancelled : public Error
{
public:
    Cancelled() : Error("cancelled") {}
};

} // namespace lic
