// The build-time master curves (laws/master_curves.hpp), read from the generated source.
#include "physics/laws/master_curves.hpp"

namespace bouncecal::laws {
namespace {

MasterNodes FromData(std::span<const double> data) {
  MasterNodes n;
  for (size_t i = 0; i + 4 < data.size(); i += 5) {
    n.damping.push_back(data[i]);
    n.restitution.push_back(data[i + 1]);
    n.restitution_slope.push_back(data[i + 2]);
    n.contact_time.push_back(data[i + 3]);
    n.contact_time_slope.push_back(data[i + 4]);
  }
  return n;
}

}  // namespace

const MasterNodes& TsujiNodes() {
  static const MasterNodes nodes = FromData(GeneratedTsujiNodeData());
  return nodes;
}

const MasterNodes& ViscoelasticNodes() {
  static const MasterNodes nodes = FromData(GeneratedViscoelasticNodeData());
  return nodes;
}

}  // namespace bouncecal::laws
