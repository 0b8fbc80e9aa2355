#!/usr/bin/python3
"""Networks: Table C.1 equivalence, exact inference form, tensor shapes, parameter counts."""

import os
import sys
import unittest

sys.path.insert(0, os.path.dirname(os.path.dirname(os.path.abspath(__file__))))

import torch  # noqa: E402

import models  # noqa: E402


def _with_batchnorm_statistics(model, seed=0):
    """Random weights and non-trivial BatchNorm running statistics, then eval mode."""
    torch.manual_seed(seed)
    models.xavier_init(model)
    for m in model.modules():
        if isinstance(m, (torch.nn.BatchNorm1d, torch.nn.BatchNorm2d)):
            m.weight.data.uniform_(0.5, 1.5)
            m.bias.data.uniform_(-0.3, 0.3)
    model.train()
    with torch.no_grad():
        for _ in range(5):
            model(torch.randn(32, 2, 5, 5) * 1.5)
    centre = torch.linspace(-0.5, 1.0, 25)
    half = torch.linspace(0.2, 1.2, 25)
    half[4::5] = 0.0  # the empty fifth column
    centre[4::5] = 0.0
    models.set_output_range(model, centre, half)
    return model.eval()


def table_c1_parameter_count(width):
    """Counted from Table C.1's rows (kernel, in/out channels, BatchNorm), not from the modules."""
    w = width
    conv = lambda k, cin, cout, bias: k * k * cin * cout + (cout if bias else 0)  # noqa: E731
    bn = lambda c: 2 * c  # noqa: E731
    total = conv(5, 2, w, True)  # no BatchNorm on the first layer
    total += conv(3, w, 2 * w, False) + bn(2 * w)
    total += conv(3, 2 * w, 4 * w, False) + bn(4 * w)
    total += conv(4, 4 * w, 8 * w, False) + bn(8 * w)
    total += conv(4, 8 * w, 4 * w, False) + bn(4 * w)  # up 1 -> 2
    total += conv(3, 8 * w, 2 * w, False) + bn(2 * w)  # up 2 -> 3, input 4w + 4w skip
    total += conv(3, 4 * w, w, False) + bn(w)  # up 3 -> 5, input 2w + 2w skip
    total += conv(5, 2 * w, 1, True)  # input w + w skip
    return total


class UNetTest(unittest.TestCase):
    def test_computes_what_the_literal_table_computes(self):
        for width in (4, 16):
            literal = _with_batchnorm_statistics(models.TableC1UNet(width), seed=width)
            ours = models.unet_from_table_c1(literal).eval()
            x = torch.randn(64, 2, 5, 5) * 1.5
            with torch.no_grad():
                gap = (ours(x) - literal(x)).abs().max().item()
            self.assertLess(gap, 1e-5, f"width {width}")
            # and not trivially: the outputs vary across inputs
            self.assertGreater(literal(x).std().item(), 0.05)

    def test_parameter_counts(self):
        self.assertEqual(models.parameter_count(models.TableC1UNet(64)), table_c1_parameter_count(64))
        self.assertEqual(models.parameter_count(models.TableC1UNet(16)), table_c1_parameter_count(16))
        # Without the 12 of 16 taps per 4x4 kernel that only see padding (enc4, dec4):
        w = 16
        dead = 12 * (4 * w * 8 * w) + 12 * (8 * w * 4 * w)
        self.assertEqual(models.parameter_count(models.UNet(w)), table_c1_parameter_count(w) - dead)

    def test_shapes_and_empty_cells(self):
        for model in (models.UNet(8), models.FCN((32, 16))):
            model = _with_batchnorm_statistics(model)
            for batch in (1, 3):
                with torch.no_grad():
                    y = model(torch.randn(batch, 2, 5, 5))
                self.assertEqual(tuple(y.shape), (batch, 1, 5, 5))
                self.assertTrue(torch.all(y[:, :, :, 4] == 0.0), "cells with half range 0 must be exactly 0")

    def test_output_stays_in_its_range(self):
        model = _with_batchnorm_statistics(models.UNet(8))
        with torch.no_grad():
            y = model(torch.randn(256, 2, 5, 5) * 10).reshape(256, 25)
        centre = model.output_range.centre.reshape(25)
        half = model.output_range.half_range.reshape(25)
        self.assertTrue(torch.all(y <= centre + half + 1e-6))
        self.assertTrue(torch.all(y >= centre - half - 1e-6))


class InferenceFormTest(unittest.TestCase):
    def test_unet_inference_form_is_exact(self):
        model = _with_batchnorm_statistics(models.UNet(16), seed=3)
        inference = models.inference_form(model)
        self.assertFalse(any(isinstance(m, torch.nn.BatchNorm2d) for m in inference.modules()))
        x = torch.randn(32, 2, 5, 5) * 1.5
        with torch.no_grad():
            self.assertLess((inference(x) - model(x)).abs().max().item(), 1e-5)

    def test_fcn_inference_form_is_exact(self):
        model = _with_batchnorm_statistics(models.FCN((64, 64, 32)), seed=4)
        inference = models.inference_form(model)
        self.assertFalse(any(isinstance(m, torch.nn.BatchNorm1d) for m in inference.modules()))
        x = torch.randn(32, 2, 5, 5) * 1.5
        with torch.no_grad():
            self.assertLess((inference(x) - model(x)).abs().max().item(), 1e-5)

    def test_zero_insert(self):
        zi = models.ZeroInsert(2, 2, 3)
        x = torch.arange(12, dtype=torch.float32).reshape(1, 2, 2, 3)
        y = zi(x)
        self.assertEqual(tuple(y.shape), (1, 2, 3, 5))
        expected = torch.zeros(1, 2, 3, 5)
        expected[:, :, ::2, ::2] = x
        self.assertTrue(torch.equal(y, expected))


if __name__ == "__main__":
    unittest.main()
