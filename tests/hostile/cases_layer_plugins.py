"""The OpenXR layer's hand-source plugins (issue 25: libproprio_source_vist.so,
libproprio_source_stretch_glove.so, loaded only when a configured source needs
one; docs/openxr-layer.md). `proprio xr-probe` runs through the loader on the
mock runtime with a glove source while PROPRIO_PLUGIN_DIR points at hostile
places: the app must run on (no hang, no crash), the layer must say which
plugin it looked for and where, and serve no hands from that source."""
from pathlib import Path

from hostile import case

PLUGIN = "libproprio_source_stretch_glove.so"

GLOVE_CONFIG = """[layer]
max_prediction_ms = 500

[[source]]
type = "glove"
input = "sim"
hands = ["right"]
space = "local"
"""

SIM_CONFIG = """[[source]]
type = "sim"
hands = ["right"]
space = "local"
"""


def xr_env(t, config, plugin_dir):
    return t.layer_env(config, {"PROPRIO_PLUGIN_DIR": str(plugin_dir)})


def probe(t, config, plugin_dir):
    return t.run("xr-probe", "--seconds", "1", "--hand", "right", env=xr_env(t, config, plugin_dir), timeout=60)


# xr-probe: 2 = XR_EXT_hand_tracking not offered / not supported, 3 = never active.
NO_HANDS = {2, 3}


@case("25 PROPRIO_PLUGIN_DIR is a FIFO: the glove source fails to start, named, and the app runs on")
def _(t):
    fifo = t.fifo("plugins")
    r = probe(t, GLOVE_CONFIG, fifo)
    r.expect(rc=NO_HANDS, err=r"glove source: PROPRIO_PLUGIN_DIR is set to '[^']*plugins', which is not a folder.*"
                              + PLUGIN)


@case("25 PROPRIO_PLUGIN_DIR is /dev/zero: not a folder, said so, no hang")
def _(t):
    r = probe(t, GLOVE_CONFIG, "/dev/zero")
    r.expect(rc=NO_HANDS, err=r"PROPRIO_PLUGIN_DIR is set to '/dev/zero', which is not a folder")


@case("25 PROPRIO_PLUGIN_DIR holds a garbage libproprio_source_stretch_glove.so: refused with dlerror's reason")
def _(t):
    t.write("plugins/" + PLUGIN, b"\x7fELF" + bytes(range(256)) * 8)
    t.watch("plugins")
    r = probe(t, GLOVE_CONFIG, t.path("plugins"))
    r.expect(rc=NO_HANDS, err=r"cannot load hand-source plugin '[^']*plugins/" + PLUGIN + r"': .*" + PLUGIN + ": ")
    t.unchanged()


@case("25 PROPRIO_PLUGIN_DIR holds a FIFO named like the plugin: refused without opening it")
def _(t):
    t.path("plugins").mkdir()
    t.fifo("plugins/" + PLUGIN)
    r = probe(t, GLOVE_CONFIG, t.path("plugins"))
    r.expect(rc=NO_HANDS, err=r"hand-source plugin '[^']*" + PLUGIN + r"' is a FIFO \(named pipe\)")


@case("25 PROPRIO_PLUGIN_DIR is an empty folder: the message names the file and the folder")
def _(t):
    t.path("plugins").mkdir()
    r = probe(t, GLOVE_CONFIG, t.path("plugins"))
    r.expect(rc=NO_HANDS, err=PLUGIN + r" was not found \(looked in '[^']*plugins'\)")


@case("25 a sim source needs no plugin: a hostile PROPRIO_PLUGIN_DIR changes nothing")
def _(t):
    r = probe(t, SIM_CONFIG, "/dev/zero")
    r.expect(rc=0, out=r"right\s+active in [1-9]\d* of ", no_err=r"hand-source plugin|PROPRIO_PLUGIN_DIR|error")


@case("25 PROPRIO_PLUGIN_DIR at the build's plugin folder: the glove source serves the right hand")
def _(t):
    plugins = Path(t.opts.layer_dir).resolve().parent / "hand_sources" / "sources"
    t.need((plugins / PLUGIN).is_file(), f"no built plugin in {plugins}")
    r = probe(t, GLOVE_CONFIG, plugins)
    r.expect(rc=0, out=r"right\s+active in [1-9]\d* of ")
