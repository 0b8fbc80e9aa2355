#!/usr/bin/python3
"""Reads the outline of an ONNX file (opset, graph inputs/outputs and their
shapes, operator types) without the `onnx` package, which Debian 12 does not
ship for Python. Enough protobuf wire format to check an export; not a general
ONNX parser.

  /usr/bin/python3 tools/stretch_glove/onnx_info.py model.onnx
"""

import json
import sys


class OnnxFormatError(Exception):
    pass


def _varint(buf, pos):
    result = 0
    shift = 0
    while True:
        if pos >= len(buf):
            raise OnnxFormatError("truncated varint")
        b = buf[pos]
        pos += 1
        result |= (b & 0x7F) << shift
        if not b & 0x80:
            return result, pos
        shift += 7
        if shift > 63:
            raise OnnxFormatError("varint longer than 10 bytes")


def _fields(buf):
    """Yields (field number, wire type, value) of one message; value is an int or bytes."""
    pos = 0
    while pos < len(buf):
        key, pos = _varint(buf, pos)
        field, wire = key >> 3, key & 7
        if wire == 0:
            value, pos = _varint(buf, pos)
        elif wire == 1:
            value, pos = buf[pos:pos + 8], pos + 8
        elif wire == 2:
            length, pos = _varint(buf, pos)
            if pos + length > len(buf):
                raise OnnxFormatError("length-delimited field runs past the end")
            value, pos = buf[pos:pos + length], pos + length
        elif wire == 5:
            value, pos = buf[pos:pos + 4], pos + 4
        else:
            raise OnnxFormatError(f"unsupported wire type {wire}")
        if pos > len(buf):
            raise OnnxFormatError("field runs past the end")
        yield field, wire, value


def _value_info(buf):
    name, dims = "", []
    for f, _, v in _fields(buf):
        if f == 1:
            name = v.decode("utf-8")
        elif f == 2:  # TypeProto
            for tf, _, tv in _fields(v):
                if tf == 1:  # tensor_type
                    for ttf, _, ttv in _fields(tv):
                        if ttf == 2:  # shape
                            for sf, _, sv in _fields(ttv):
                                if sf == 1:  # dim
                                    dim = None
                                    for df, _, dv in _fields(sv):
                                        if df == 1:
                                            dim = dv
                                        elif df == 2:
                                            dim = dv.decode("utf-8")
                                    dims.append(dim)
    return name, dims


def read(path):
    """{"opset": int, "producer": str, "inputs": {name: dims}, "outputs": {...}, "ops": [op types]}"""
    with open(path, "rb") as f:
        buf = f.read()
    info = {"opset": None, "producer": "", "inputs": {}, "outputs": {}, "ops": [], "initializers": 0}
    graph = None
    for f, wire, v in _fields(buf):
        if f == 2 and wire == 2:
            info["producer"] = v.decode("utf-8", "replace")
        elif f == 7 and wire == 2:
            graph = v
        elif f == 8 and wire == 2:
            domain, version = "", None
            for of, _, ov in _fields(v):
                if of == 1:
                    domain = ov.decode("utf-8")
                elif of == 2:
                    version = ov
            if domain in ("", "ai.onnx"):
                info["opset"] = version
    if graph is None:
        raise OnnxFormatError(f"{path}: no graph (not an ONNX model)")
    initializer_names = set()
    inputs = []
    for f, _, v in _fields(graph):
        if f == 1:
            for nf, _, nv in _fields(v):
                if nf == 4:
                    info["ops"].append(nv.decode("utf-8"))
        elif f == 5:
            info["initializers"] += 1
            for tf, _, tv in _fields(v):
                if tf == 8:
                    initializer_names.add(tv.decode("utf-8"))
        elif f == 11:
            inputs.append(_value_info(v))
        elif f == 12:
            name, dims = _value_info(v)
            info["outputs"][name] = dims
    for name, dims in inputs:
        if name not in initializer_names:
            info["inputs"][name] = dims
    return info


if __name__ == "__main__":
    if len(sys.argv) != 2:
        print("usage: onnx_info.py MODEL.onnx", file=sys.stderr)
        sys.exit(2)
    try:
        print(json.dumps(read(sys.argv[1]), indent=1))
    except (OSError, OnnxFormatError) as e:
        print(f"error: {e}", file=sys.stderr)
        sys.exit(1)
