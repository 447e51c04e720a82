// A directory as a ZIP archive (include/bouncecal/serve/zip.hpp). The format: PKWARE's
// APPNOTE.TXT 6.3, sections 4.3.7 (local file header), 4.3.12 (central directory header) and
// 4.3.16 (end of central directory record); stored entries (method 0).
#include "bouncecal/serve/zip.hpp"

#include <sys/stat.h>

#include <algorithm>
#include <cstdint>
#include <ctime>
#include <filesystem>
#include <fstream>
#include <iterator>
#include <vector>

#include <boost/crc.hpp>

#include "bouncecal/core/error.hpp"

namespace bouncecal::serve {
namespace {

void Put16(std::string* out, std::uint32_t v) {
  out->push_back(static_cast<char>(v & 0xff));
  out->push_back(static_cast<char>((v >> 8) & 0xff));
}
void Put32(std::string* out, std::uint32_t v) {
  Put16(out, v & 0xffff);
  Put16(out, v >> 16);
}

// MS-DOS date and time (APPNOTE 4.4.6), local time as unzip shows it; 1980 at the earliest.
std::pair<std::uint32_t, std::uint32_t> DosTime(std::time_t t) {
  std::tm tm{};
  localtime_r(&t, &tm);
  if (tm.tm_year < 80) return {0, (1u << 5) | 1u};  // 1980-01-01 00:00
  const auto time =
      static_cast<std::uint32_t>((tm.tm_hour << 11) | (tm.tm_min << 5) | (tm.tm_sec / 2));
  const auto date =
      static_cast<std::uint32_t>(((tm.tm_year - 80) << 9) | ((tm.tm_mon + 1) << 5) | tm.tm_mday);
  return {time, date};
}

struct Entry {
  std::string name;
  std::uint32_t crc = 0, size = 0, time = 0, date = 0, mode = 0, offset = 0;
};

}  // namespace

std::string ZipDirectory(const std::string& dir, const std::string& prefix) {
  namespace fs = std::filesystem;
  std::vector<fs::path> files;
  for (const auto& e : fs::recursive_directory_iterator(dir))
    if (e.is_regular_file()) files.push_back(e.path());
  std::sort(files.begin(), files.end());
  if (files.size() > 65535) throw Error(ErrorCode::kOutput, dir + ": too many files for a ZIP");
  std::string out;
  std::vector<Entry> entries;
  constexpr std::uint32_t kUtf8Names = 1u << 11;
  for (const fs::path& p : files) {
    std::ifstream in(p, std::ios::binary);
    const std::string data((std::istreambuf_iterator<char>(in)), std::istreambuf_iterator<char>());
    if (!in.good() && !in.eof()) throw Error(ErrorCode::kOutput, p.string() + ": cannot be read");
    struct stat st {};
    if (::stat(p.c_str(), &st) != 0)
      throw Error(ErrorCode::kOutput, p.string() + ": cannot be read");
    if (out.size() + data.size() > 0xfff00000u)
      throw Error(ErrorCode::kOutput, dir + ": too large for a ZIP without ZIP64");
    boost::crc_32_type crc;
    crc.process_bytes(data.data(), data.size());
    Entry e;
    e.name = prefix + "/" + fs::relative(p, dir).generic_string();
    e.crc = crc.checksum();
    e.size = static_cast<std::uint32_t>(data.size());
    std::tie(e.time, e.date) = DosTime(st.st_mtime);
    e.mode = static_cast<std::uint32_t>(st.st_mode & 0xffff);
    e.offset = static_cast<std::uint32_t>(out.size());
    Put32(&out, 0x04034b50);  // local file header
    Put16(&out, 20);          // version needed: 2.0
    Put16(&out, kUtf8Names);
    Put16(&out, 0);  // stored
    Put16(&out, e.time);
    Put16(&out, e.date);
    Put32(&out, e.crc);
    Put32(&out, e.size);
    Put32(&out, e.size);
    Put16(&out, static_cast<std::uint32_t>(e.name.size()));
    Put16(&out, 0);
    out += e.name;
    out += data;
    entries.push_back(std::move(e));
  }
  const auto directory = static_cast<std::uint32_t>(out.size());
  for (const Entry& e : entries) {
    Put32(&out, 0x02014b50);       // central directory header
    Put16(&out, (3u << 8) | 20u);  // made by: Unix, 2.0 (the external attributes are a mode)
    Put16(&out, 20);
    Put16(&out, kUtf8Names);
    Put16(&out, 0);
    Put16(&out, e.time);
    Put16(&out, e.date);
    Put32(&out, e.crc);
    Put32(&out, e.size);
    Put32(&out, e.size);
    Put16(&out, static_cast<std::uint32_t>(e.name.size()));
    Put16(&out, 0);  // extra
    Put16(&out, 0);  // comment
    Put16(&out, 0);  // disk
    Put16(&out, 0);  // internal attributes
    Put32(&out, e.mode << 16);
    Put32(&out, e.offset);
    out += e.name;
  }
  const auto directory_size = static_cast<std::uint32_t>(out.size()) - directory;
  Put32(&out, 0x06054b50);  // end of central directory
  Put16(&out, 0);
  Put16(&out, 0);
  Put16(&out, static_cast<std::uint32_t>(entries.size()));
  Put16(&out, static_cast<std::uint32_t>(entries.size()));
  Put32(&out, directory_size);
  Put32(&out, directory);
  Put16(&out, 0);
  return out;
}

}  // namespace bouncecal::serve
