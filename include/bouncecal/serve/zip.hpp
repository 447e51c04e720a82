// bouncecal/serve/zip.hpp — a directory as a ZIP archive (the export decks the page downloads).
//
// Stored entries (no compression: a deck is a few kB of text), CRC-32 from Boost.CRC, UTF-8
// names, each file's Unix mode kept (run.sh stays executable when unzipped with `unzip`), times
// from the files' modification times. Every regular file under `dir`, sorted, as
// "<prefix>/<path below dir>". Throws Error(kOutput) naming the file that cannot be read, or an
// archive beyond the classic format's 4 GiB / 65535 entries.
//
//   const std::string zip = ZipDirectory("/tmp/x/bounce_lammps", "bounce_lammps");
#pragma once

#include <string>

namespace bouncecal::serve {

std::string ZipDirectory(const std::string& dir, const std::string& prefix);

}  // namespace bouncecal::serve
