#!/usr/bin/python3
"""Makes the ONNX regressors the stretch_array_recon tests and benchmark read.

The contract (input/stretch_array_recon/include/proprio/stretch_array_recon/
marker_regressor.hpp): input "cells" float32 [1, C] (capacitance ratios
C/C0), output "markers" float32 [1, 3M] in metres, marker-major.

  make_models.py tiny   -> tiny_regressor.onnx/.json and tiny_expected.json,
                           lr_grid9.onnx/.json (a linear regressor with known
                           outputs for the reconstructor's tests); committed:
                           the unit tests compare against these
  make_models.py thesis OUT_DIR [C M]
                        -> OUT_DIR/thesis_regressor.onnx/.json: the thesis's
                           Fig. 4.13 network (C -> 3 x FC 2048 -> FC 1024 ->
                           3M, ReLU + BatchNorm after the input and every
                           hidden layer), about 10M parameters = 40 MB: for the
                           benchmark only, never committed.

Weights are random (seeded): these files test the runtime, not a trained
regressor. Run with Debian's python3 and torch 1.13.
"""
import json
import os
import sys

import torch
from torch import nn

HERE = os.path.dirname(os.path.abspath(__file__))


class Regressor(nn.Module):
    def __init__(self, cells, markers, hidden):
        super().__init__()
        layers = []
        width = cells
        # The thesis: "The input and all hidden layers are followed by a ReLu
        # activation function and a BatchNorm layer."
        for h in hidden:
            layers += [nn.Linear(width, h), nn.ReLU(), nn.BatchNorm1d(h)]
            width = h
        layers.append(nn.Linear(width, 3 * markers))
        self.net = nn.Sequential(*layers)

    def forward(self, cells):
        # The normalisation lives inside the model: ratios near 1 -> around 0.
        return self.net((cells - 1.0) * 10.0)


class Linear9(nn.Module):
    def __init__(self):
        super().__init__()
        import math
        self.fc = nn.Linear(9, 12)
        c, s = math.cos(math.radians(30)), math.sin(math.radians(30))
        bias = []
        for x, y in [(0.0, 0.0), (0.024, 0.0), (0.0, 0.024), (0.024, 0.024)]:
            bias += [c * x - s * y + 0.1, s * x + c * y + 0.2, 0.3]
        with torch.no_grad():
            self.fc.weight.zero_()
            self.fc.weight[3 * 3 + 2, 0] = 0.05
            self.fc.bias.copy_(torch.tensor(bias))

    def forward(self, cells):
        return self.fc(cells - 1.0)


def randomise_batchnorm(model, gen):
    # Non-trivial running statistics so a runtime that ignored BatchNorm fails.
    for m in model.modules():
        if isinstance(m, nn.BatchNorm1d):
            n = m.num_features
            m.running_mean.copy_(torch.rand(n, generator=gen) * 0.2)
            m.running_var.copy_(0.5 + torch.rand(n, generator=gen))
            m.weight.data.copy_(0.5 + torch.rand(n, generator=gen))
            m.bias.data.copy_(torch.randn(n, generator=gen) * 0.1)


def export(model, cells, markers, path, kind):
    model.eval()
    dummy = torch.ones(1, cells)
    torch.onnx.export(model, dummy, path, input_names=["cells"], output_names=["markers"], opset_version=11,
                      do_constant_folding=True)
    params = sum(p.numel() for p in model.parameters())
    with open(os.path.splitext(path)[0] + ".json", "w") as f:
        json.dump({"format": "proprio-stretch-array-regressor", "cell_count": cells, "marker_count": markers,
                   "kind": kind, "parameters": params, "torch_version": torch.__version__}, f, indent=2)
        f.write("\n")
    return params


def main():
    what = sys.argv[1] if len(sys.argv) > 1 else "tiny"
    gen = torch.Generator().manual_seed(30)
    torch.manual_seed(30)
    if what == "tiny":
        cells, markers = 6, 2
        model = Regressor(cells, markers, [8, 5])
        randomise_batchnorm(model, gen)
        export(model, cells, markers, os.path.join(HERE, "tiny_regressor.onnx"), "dnn")
        inputs = [[1.0] * cells, [1.0 + 0.05 * i for i in range(cells)], [0.9, 1.2, 1.1, 1.0, 1.3, 0.95]]
        with torch.no_grad():
            outputs = model(torch.tensor(inputs, dtype=torch.float32)).tolist()
        with open(os.path.join(HERE, "tiny_expected.json"), "w") as f:
            json.dump({"inputs": inputs, "outputs": outputs}, f, indent=2)
            f.write("\n")
        for i, o in zip(inputs, outputs):
            print(i, "->", o)
        # A linear ("lr") regressor for a 3 x 3 grid at 12 mm (9 cells) with
        # markers on the four corner cells, (0,0), (24,0), (0,24), (24,24) mm
        # on the flat sheet: at rest it gives those points moved rigidly (30
        # degrees about z, then (0.1, 0.2, 0.3) m); cell 0 lifts marker 3.
        lr = Linear9()
        export(lr, 9, 4, os.path.join(HERE, "lr_grid9.onnx"), "lr")
        with torch.no_grad():
            print("lr_grid9 at rest:", lr(torch.ones(1, 9)).tolist())
    elif what == "thesis":
        out_dir = sys.argv[2]
        cells = int(sys.argv[3]) if len(sys.argv) > 3 else 92
        markers = int(sys.argv[4]) if len(sys.argv) > 4 else 21
        model = Regressor(cells, markers, [2048, 2048, 2048, 1024])
        randomise_batchnorm(model, gen)
        params = export(model, cells, markers, os.path.join(out_dir, "thesis_regressor.onnx"), "dnn")
        print("thesis regressor:", cells, "cells,", markers, "markers,", params, "parameters")
    else:
        sys.exit("usage: make_models.py tiny | thesis OUT_DIR [CELLS MARKERS]")


if __name__ == "__main__":
    main()
