#pragma once
// The stretch glove's read-out: the matrix read-out every capacitive array
// shares (stretch_array/matrix_readout.hpp, where the solve, its robustness
// and its timing are described), over the glove layout's measurement matrix
// and its cells' rest capacitances.
#include "proprio/core/result.hpp"
#include "proprio/glove_descriptions/stretch_glove_layout.hpp"
#include "proprio/stretch_array/matrix_readout.hpp"

namespace proprio::stretch_glove {

using stretch_array::CellFrame;
using stretch_array::CellStatus;
using stretch_array::MatrixReadout;
using stretch_array::ReadoutOptions;

// Errors when the options are unusable or the layout is invalid (its
// validate() refuses a rank-deficient measurement matrix, naming the cells).
Result<MatrixReadout> make_readout(const StretchGloveLayout& layout, ReadoutOptions options = {});

}  // namespace proprio::stretch_glove
