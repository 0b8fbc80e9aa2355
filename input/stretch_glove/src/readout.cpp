#include "proprio/stretch_glove/readout.hpp"

#include <utility>
#include <vector>

namespace proprio::stretch_glove {

Result<MatrixReadout> make_readout(const StretchGloveLayout& layout, ReadoutOptions options) {
  if (auto st = layout.validate(); !st) return st.error();
  std::vector<double> rest_pf;
  rest_pf.reserve(layout.cells.size());
  for (const auto& c : layout.cells) rest_pf.push_back(c.rest_capacitance_pf);
  return MatrixReadout::create(layout.measurement_matrix(), std::move(rest_pf), options);
}

}  // namespace proprio::stretch_glove
