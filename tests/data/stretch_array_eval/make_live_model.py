#!/usr/bin/python3
"""Makes the regressor the live array source's tests read (test_array_live.cpp).

  make_live_model.py  -> tiny_p92.onnx/.json: a linear ("lr") regressor for
                         prototype_92 (92 cells in, 19 markers out: the
                         markers select_marker_vertices() picks at its
                         default 35 mm), seeded random weights and a grid of
                         marker positions as the bias, 5301 parameters.

It tests the runtime (the ONNX contract of marker_regressor.hpp, sizes, the
live threads), not a trained regressor: `proprio sim-array` and `proprio train
array` make real ones. Run with Debian's python3 and torch 1.13.
"""
import json
import os

import torch
from torch import nn

HERE = os.path.dirname(os.path.abspath(__file__))
CELLS, MARKERS = 92, 19


class Linear(nn.Module):
    def __init__(self, gen):
        super().__init__()
        self.fc = nn.Linear(CELLS, 3 * MARKERS)
        with torch.no_grad():
            self.fc.weight.copy_(torch.randn(3 * MARKERS, CELLS, generator=gen) * 1e-3)
            bias = []
            for m in range(MARKERS):
                bias += [0.03 * (m % 5), 0.03 * (m // 5), 0.0]
            self.fc.bias.copy_(torch.tensor(bias))

    def forward(self, cells):
        return self.fc(cells - 1.0)


def main():
    gen = torch.Generator().manual_seed(30)
    model = Linear(gen)
    model.eval()
    path = os.path.join(HERE, "tiny_p92.onnx")
    torch.onnx.export(model, torch.ones(1, CELLS), path, input_names=["cells"], output_names=["markers"],
                      opset_version=11, do_constant_folding=True)
    params = sum(p.numel() for p in model.parameters())
    with open(os.path.splitext(path)[0] + ".json", "w") as f:
        json.dump({"format": "proprio-stretch-array-regressor", "cell_count": CELLS, "marker_count": MARKERS,
                   "kind": "lr", "parameters": params, "torch_version": torch.__version__}, f, indent=2)
        f.write("\n")
    print("wrote", path, params, "parameters")


if __name__ == "__main__":
    main()
