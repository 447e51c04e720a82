// bouncecal/serve/page.hpp — the server's one page (src/serve/page/: serve.html with serve.css
// and serve.js inlined at build time by cmake/embed_serve_page.cmake, as the report's are).
// Self-contained: nothing is fetched from the network (the build stops on a URL in it).
#pragma once

#include <string_view>

namespace bouncecal::serve {

std::string_view PageHtml();

}  // namespace bouncecal::serve
