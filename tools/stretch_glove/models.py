#!/usr/bin/python3
"""Pose networks for the stretch-sensing glove (Glauser 2019, sec. 5.3.2 and Appendix C.1).

Both networks read the same tensor, float32 NCHW [B, 2, 5, 5] ("stretch": the
normalised cells on their along/across grids, empty slots 0), and write the same
tensor, [B, 1, 5, 5] ("pose": joint angles in radians on the output grid).

U-Net, Table C.1, with these readings and adaptations (see README.md):
  * Skip connections concatenate (Ronneberger 2015; the thesis's CGAN generator
    "has the same structure"). Table C.1's input column lists the decoder's
    shapes before concatenation.
  * The decoder's "CONV-(N512, K4x4, S2, P1)" rows are transposed convolutions
    (the only way to go 1x1 -> 2x2 -> 3x3 -> 5x5 with those kernels); their output
    channels are the table's output shapes (256, 128, 64), not its N column.
  * Layers are written so that PyTorch trains them fast on a CPU and OpenCV 4.6
    runs them fast, computing exactly the function of the table's layers on a
    5x5 grid: ConvTranspose k3/s2 = zero insertion + 3x3 convolution; the 1x1 ->
    2x2 ConvTranspose = 1x1 convolution to 4C channels + Reshape; the 2x2 -> 1x1
    K4 convolution keeps only the taps that see data (TableC1UNet is the
    literal table; a test checks the two agree).
  * Channel width is a parameter: width 64 is Table C.1 (5.31 M parameters as
    written, 2.16 M that ever touch data; the thesis text's "13M" cannot come
    from this table). The default is width 16 (333 k as written, 137 k live):
    OpenCV 4.6 needs about 100 us per frame for it on one core, within the 200
    us budget (width 32: 300 us, width 64: 1.4 ms), and the thesis found 3 M
    vs 13 M vs 50 M within 0.2 deg (Tables 5.4-5.5) on far more data than a
    simulator run gives us.
The final Tanh of Table C.1 is kept; it is scaled per output cell to the range
the training angles cover (plus a margin), so the net outputs radians directly
and empty output cells are exactly 0.

FCN baseline (Appendix C.1 / Fig. 4.13): Linear -> ReLU -> BatchNorm per hidden
layer. The thesis's F2048x4-F1024 (15 M parameters) is replaced by default by
hidden widths 384-384-384-192 (0.40 M), sized like the default U-Net as the
thesis matched sizes in Table 5.4.

For export, `inference_form()` folds every BatchNorm into the neighbouring
convolution or Linear (OpenCV 4.6 re-fuses BatchNorm wrongly when a Net sees a
second input shape; docs/platform-notes.md).
"""

import math
import os

# See training.py: passive OpenMP waiting, set before torch loads.
os.environ.setdefault("OMP_WAIT_POLICY", "PASSIVE")

import torch  # noqa: E402
from torch import nn  # noqa: E402

GRID = 5
INPUT_LAYERS = 2
CELLS_OUT = GRID * GRID

MODEL_KINDS = ("unet", "fcn")


class OutputRange(nn.Module):
    """tanh(z) * half_range + centre, per output cell (buffers, not trained).

    Empty output cells have half_range = centre = 0, so they are exactly 0.
    """

    def __init__(self, centre=None, half_range=None):
        super().__init__()
        self.register_buffer("centre", torch.zeros(1, 1, GRID, GRID) if centre is None else centre)
        self.register_buffer("half_range", torch.ones(1, 1, GRID, GRID) if half_range is None else half_range)

    def forward(self, z):
        return torch.tanh(z) * self.half_range + self.centre


def _conv_bn_relu(c_in, c_out, kernel, stride, padding, batch_norm=True):
    layers = [nn.Conv2d(c_in, c_out, kernel, stride, padding, bias=not batch_norm)]
    if batch_norm:
        layers.append(nn.BatchNorm2d(c_out))
    layers.append(nn.ReLU(inplace=False))
    return nn.Sequential(*layers)


def _up_bn_relu(c_in, c_out, kernel, stride, padding):
    return nn.Sequential(
        nn.ConvTranspose2d(c_in, c_out, kernel, stride, padding, bias=False),
        nn.BatchNorm2d(c_out),
        nn.ReLU(inplace=False),
    )


class ZeroInsert(nn.Module):
    """Puts a zero between neighbouring pixels: HxW -> (2H-1)x(2W-1).

    A product with a constant 0/1 matrix on the flattened pixels: OpenCV runs it
    as an InnerProduct in about 3 us (a depthwise ConvTranspose k1/s2 took 20-30
    us), and PyTorch's CPU ConvTranspose (slow_conv_transpose2d in Debian's
    build) was two orders of magnitude slower to train than this.
    """

    def __init__(self, channels, height, width):
        super().__init__()
        # Fixed sizes keep the export free of Shape/Gather ops (OpenCV 4.6 handles few of those).
        self.channels, self.height, self.width = channels, height, width
        self.out_height, self.out_width = 2 * height - 1, 2 * width - 1
        spread = torch.zeros(height * width, self.out_height * self.out_width)
        for y in range(height):
            for x in range(width):
                spread[y * width + x, 2 * y * self.out_width + 2 * x] = 1.0
        self.register_buffer("spread", spread)

    def forward(self, x):
        flat = x.reshape(-1, self.height * self.width) @ self.spread
        return flat.reshape(-1, self.channels, self.out_height, self.out_width)


class UpConv(nn.Module):
    """Table C.1's up-convolution (ConvTranspose k3, s2, p1) as zero insertion
    plus a 3x3 convolution: the same function (the convolution's kernel is the
    transposed one's, rotated by 180 degrees)."""

    def __init__(self, c_in, c_out, in_size, batch_norm=True):
        super().__init__()
        self.zero_insert = ZeroInsert(c_in, in_size, in_size)
        self.conv = nn.Conv2d(c_in, c_out, 3, 1, 1, bias=not batch_norm)
        self.norm = nn.BatchNorm2d(c_out) if batch_norm else None

    def forward(self, x):
        y = self.conv(self.zero_insert(x))
        y = self.norm(y) if self.norm is not None else y
        return torch.relu(y)


class OneToTwo(nn.Module):
    """Table C.1's first up-convolution (ConvTranspose k4, s2, p1; 1x1 -> 2x2):
    on a 1x1 input, output pixel (y, x) only sees kernel tap (y+1, x+1), so it
    is a 1x1 convolution to 4C channels, reshaped (channel o*4 + y*2 + x lands
    at (o, y, x)). The other 12 taps of the 4x4 kernel never touch data."""

    def __init__(self, c_in, c_out, batch_norm=True):
        super().__init__()
        self.c_out = c_out
        self.conv = nn.Conv2d(c_in, 4 * c_out, 1, bias=not batch_norm)
        self.norm = nn.BatchNorm2d(c_out) if batch_norm else None

    def forward(self, x):
        y = self.conv(x).reshape(-1, self.c_out, 2, 2)
        y = self.norm(y) if self.norm is not None else y
        return torch.relu(y)


class UNet(nn.Module):
    """Table C.1 at channel width `width` (64 = the thesis's table), on the 5x5 grid.

    Each layer computes exactly the function of the Table C.1 layer it stands
    for (tested against a literal ConvTranspose version, TableC1UNet), but
    without kernel taps that only ever multiply zero padding on a 5x5 input:
    enc4 (K4 S2 P1 on a 2x2 map) keeps its 2x2 interior, dec4 its 2x2 centre.
    """

    def __init__(self, width=16):
        super().__init__()
        w = int(width)
        if w < 1:
            raise ValueError(f"U-Net width must be >= 1, got {width}")
        self.width = w
        # Table C.1: the first layer has no BatchNorm.
        self.enc1 = _conv_bn_relu(INPUT_LAYERS, w, 5, 1, 2, batch_norm=False)  # 5x5
        self.enc2 = _conv_bn_relu(w, 2 * w, 3, 2, 1)  # 3x3
        self.enc3 = _conv_bn_relu(2 * w, 4 * w, 3, 2, 1)  # 2x2
        self.enc4 = _conv_bn_relu(4 * w, 8 * w, 2, 1, 0)  # 1x1 (K4 S2 P1's interior taps)
        self.dec4 = OneToTwo(8 * w, 4 * w)  # 1x1 -> 2x2
        self.dec3 = UpConv(8 * w, 2 * w, 2)  # 2x2 -> 3x3
        self.dec2 = UpConv(4 * w, w, 3)  # 3x3 -> 5x5
        self.head = nn.Conv2d(2 * w, 1, 5, 1, 2)
        self.output_range = OutputRange()

    def forward(self, x):
        e1 = self.enc1(x)
        e2 = self.enc2(e1)
        e3 = self.enc3(e2)
        e4 = self.enc4(e3)
        d4 = torch.cat([self.dec4(e4), e3], dim=1)
        d3 = torch.cat([self.dec3(d4), e2], dim=1)
        d2 = torch.cat([self.dec2(d3), e1], dim=1)
        return self.output_range(self.head(d2))


class TableC1UNet(nn.Module):
    """Table C.1 taken literally (ConvTranspose2d decoder, 4x4 kernels at the
    bottleneck). Not trained (PyTorch's CPU ConvTranspose is very slow here);
    kept to test that UNet computes the same function and to count the
    table's parameters."""

    def __init__(self, width=16):
        super().__init__()
        w = int(width)
        self.width = w
        self.enc1 = _conv_bn_relu(INPUT_LAYERS, w, 5, 1, 2, batch_norm=False)
        self.enc2 = _conv_bn_relu(w, 2 * w, 3, 2, 1)
        self.enc3 = _conv_bn_relu(2 * w, 4 * w, 3, 2, 1)
        self.enc4 = _conv_bn_relu(4 * w, 8 * w, 4, 2, 1)
        self.dec4 = _up_bn_relu(8 * w, 4 * w, 4, 2, 1)
        self.dec3 = _up_bn_relu(8 * w, 2 * w, 3, 2, 1)
        self.dec2 = _up_bn_relu(4 * w, w, 3, 2, 1)
        self.head = nn.Conv2d(2 * w, 1, 5, 1, 2)
        self.output_range = OutputRange()

    def forward(self, x):
        e1 = self.enc1(x)
        e2 = self.enc2(e1)
        e3 = self.enc3(e2)
        e4 = self.enc4(e3)
        d4 = torch.cat([self.dec4(e4), e3], dim=1)
        d3 = torch.cat([self.dec3(d4), e2], dim=1)
        d2 = torch.cat([self.dec2(d3), e1], dim=1)
        return self.output_range(self.head(d2))


def unet_from_table_c1(literal):
    """A UNet computing exactly what a TableC1UNet computes on 5x5 inputs."""
    w = literal.width
    unet = UNet(w)
    with torch.no_grad():
        unet.enc1.load_state_dict(literal.enc1.state_dict())
        unet.enc2.load_state_dict(literal.enc2.state_dict())
        unet.enc3.load_state_dict(literal.enc3.state_dict())
        unet.enc4[0].weight.copy_(literal.enc4[0].weight[:, :, 1:3, 1:3])
        unet.enc4[1].load_state_dict(literal.enc4[1].state_dict())
        taps = literal.dec4[0].weight[:, :, 1:3, 1:3]  # [in, out, y, x]
        unet.dec4.conv.weight.copy_(taps.permute(1, 2, 3, 0).reshape(4 * 4 * w, 8 * w, 1, 1))
        unet.dec4.norm.load_state_dict(literal.dec4[1].state_dict())
        for ours, theirs in ((unet.dec3, literal.dec3), (unet.dec2, literal.dec2)):
            ours.conv.weight.copy_(theirs[0].weight.permute(1, 0, 2, 3).flip(2, 3))
            ours.norm.load_state_dict(theirs[1].state_dict())
        unet.head.load_state_dict(literal.head.state_dict())
        unet.output_range.load_state_dict(literal.output_range.state_dict())
    return unet


class FCN(nn.Module):
    """Fully connected baseline on the same tensors (the 2x5x5 input flattened)."""

    def __init__(self, hidden=(384, 384, 384, 192)):
        super().__init__()
        hidden = tuple(int(h) for h in hidden)
        if not hidden or min(hidden) < 1:
            raise ValueError(f"FCN hidden widths must be positive, got {hidden}")
        self.hidden = hidden
        layers = []
        c_in = INPUT_LAYERS * GRID * GRID
        for h in hidden:
            layers += [nn.Linear(c_in, h), nn.ReLU(inplace=False), nn.BatchNorm1d(h)]
            c_in = h
        self.trunk = nn.Sequential(*layers)
        self.out = nn.Linear(c_in, CELLS_OUT)
        self.output_range = OutputRange()

    def forward(self, x):
        z = self.out(self.trunk(torch.flatten(x, 1)))
        return self.output_range(z.reshape(-1, 1, GRID, GRID))


def xavier_init(model):
    """Xavier weights (Appendix C.1), zero biases; BatchNorm left at identity."""
    for m in model.modules():
        if isinstance(m, (nn.Conv2d, nn.ConvTranspose2d, nn.Linear)):
            nn.init.xavier_uniform_(m.weight)
            if m.bias is not None:
                nn.init.zeros_(m.bias)


def build_model(kind, unet_width=16, fcn_hidden=(384, 384, 384, 192)):
    if kind == "unet":
        return UNet(unet_width)
    if kind == "fcn":
        return FCN(fcn_hidden)
    raise ValueError(f"unknown model kind '{kind}': expected one of {', '.join(MODEL_KINDS)}")


def model_config(model):
    """What build_model() needs to rebuild `model` (stored in model.pt and model.json)."""
    if isinstance(model, UNet):
        return {"kind": "unet", "unet_width": model.width}
    if isinstance(model, FCN):
        return {"kind": "fcn", "fcn_hidden": list(model.hidden)}
    raise TypeError(f"not a stretch-glove model: {type(model).__name__}")


def build_from_config(config):
    if config["kind"] == "unet":
        return UNet(config["unet_width"])
    return build_model(config["kind"], fcn_hidden=config.get("fcn_hidden", (384, 384, 384, 192)))


def parameter_count(model):
    return sum(p.numel() for p in model.parameters())


# --------------------------------------------------------------------------
# Inference form: exactly equivalent, built for OpenCV 4.6 DNN.
# --------------------------------------------------------------------------

def _bn_scale_shift(bn):
    scale = bn.weight.detach() / torch.sqrt(bn.running_var + bn.eps)
    shift = bn.bias.detach() - bn.running_mean * scale
    return scale, shift


def _folded_conv(conv, bn):
    """Conv2d with its BatchNorm folded in (eval statistics)."""
    scale, shift = _bn_scale_shift(bn)
    folded = nn.Conv2d(conv.in_channels, conv.out_channels, conv.kernel_size, conv.stride, conv.padding, bias=True)
    folded.weight.data = conv.weight.detach() * scale.view(-1, 1, 1, 1)
    bias = conv.bias.detach() if conv.bias is not None else torch.zeros(conv.out_channels)
    folded.bias.data = bias * scale + shift
    return folded


def _folded_up(up):
    folded = UpConv(up.conv.in_channels, up.conv.out_channels, up.zero_insert.height, batch_norm=False)
    folded.conv = _folded_conv(up.conv, up.norm)
    return folded


def _folded_one_to_two(layer):
    scale, shift = _bn_scale_shift(layer.norm)
    folded = OneToTwo(layer.conv.in_channels, layer.c_out, batch_norm=False)
    # Output channel o*4 + k belongs to BatchNorm channel o.
    folded.conv.weight.data = layer.conv.weight.detach() * scale.repeat_interleave(4).view(-1, 1, 1, 1)
    folded.conv.bias.data = shift.repeat_interleave(4)
    return folded


class UNetInference(nn.Module):
    def __init__(self, unet):
        super().__init__()
        self.enc1 = unet.enc1
        self.enc2 = nn.Sequential(_folded_conv(unet.enc2[0], unet.enc2[1]), nn.ReLU())
        self.enc3 = nn.Sequential(_folded_conv(unet.enc3[0], unet.enc3[1]), nn.ReLU())
        self.enc4 = nn.Sequential(_folded_conv(unet.enc4[0], unet.enc4[1]), nn.ReLU())
        self.dec4 = _folded_one_to_two(unet.dec4)
        self.dec3 = _folded_up(unet.dec3)
        self.dec2 = _folded_up(unet.dec2)
        self.head = unet.head
        self.output_range = unet.output_range

    def forward(self, x):
        e1 = self.enc1(x)
        e2 = self.enc2(e1)
        e3 = self.enc3(e2)
        e4 = self.enc4(e3)
        d4 = torch.cat([self.dec4(e4), e3], dim=1)
        d3 = torch.cat([self.dec3(d4), e2], dim=1)
        d2 = torch.cat([self.dec2(d3), e1], dim=1)
        return self.output_range(self.head(d2))


class FCNInference(nn.Module):
    """BatchNorm (after ReLU) folded into the next Linear."""

    def __init__(self, fcn):
        super().__init__()
        linears = [m for m in fcn.trunk if isinstance(m, nn.Linear)]
        norms = [m for m in fcn.trunk if isinstance(m, nn.BatchNorm1d)]
        layers = []
        pending = None  # (scale, shift) of the BatchNorm before the next Linear
        for lin, bn in zip(linears + [fcn.out], norms + [None]):
            folded = nn.Linear(lin.in_features, lin.out_features)
            w = lin.weight.detach().clone()
            b = lin.bias.detach().clone()
            if pending is not None:
                scale, shift = pending
                b = b + w @ shift
                w = w * scale.view(1, -1)
            folded.weight.data = w
            folded.bias.data = b
            layers.append(folded)
            pending = _bn_scale_shift(bn) if bn is not None else None
        self.hidden = nn.ModuleList(layers[:-1])
        self.out = layers[-1]
        self.output_range = fcn.output_range

    def forward(self, x):
        h = torch.flatten(x, 1)
        for lin in self.hidden:
            h = torch.relu(lin(h))
        return self.output_range(self.out(h).reshape(-1, 1, GRID, GRID))


def inference_form(model):
    """An exactly equivalent eval-mode model for ONNX export (see module doc)."""
    model = model.eval()
    with torch.no_grad():
        if isinstance(model, UNet):
            return UNetInference(model).eval()
        if isinstance(model, FCN):
            return FCNInference(model).eval()
    raise TypeError(f"not a stretch-glove model: {type(model).__name__}")


def set_output_range(model, centre, half_range):
    """centre, half_range: [25] tensors (radians) per output cell."""
    model.output_range.centre.copy_(torch.as_tensor(centre, dtype=torch.float32).view(1, 1, GRID, GRID))
    model.output_range.half_range.copy_(torch.as_tensor(half_range, dtype=torch.float32).view(1, 1, GRID, GRID))


def degrees(radians):
    return radians * 180.0 / math.pi
