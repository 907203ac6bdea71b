//! The C ABI's tests, one binary: the committed header is cbindgen's
//! (`header`), the C program over the golden vectors at -O0 and -O2 and
//! the header as C++ (`c_program`), the MEX gateway in Octave (`octave`),
//! docs/rigs.md's controller snippets compiled against the header
//! (`snippets`).

mod c_program;
mod header;
mod octave;
mod snippets;
mod support;
