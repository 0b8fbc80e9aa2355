"""Fingertip haptics in the OpenXR layer (issue 29): a bad [haptics] table
stops the config with the file and what is allowed; a hostile device model
named by it costs the app its fingertip devices, said in the log, and the app
runs on without a hang (docs/xr-proprio-fingertip-haptics.md)."""

from hostile import case

SOURCE = '[[source]]\ntype = "sim"\nspace = "local"\n'
HAPTICS = '[haptics]\ndevices = "emulated"\nright = ["index"]\n'


def status(t, config):
    return t.layer_status(config)


def probe(t, config):
    return t.run("xr-probe", "--seconds", "1", "--hand", "right", "--space", "local", env=t.layer_env(config), timeout=90)


@case("29 [haptics] with an unknown finger, a finger twice, or no fingers: refused, the finger or the fix named")
def _(t):
    status(t, SOURCE + '[haptics]\nright = ["pinky"]\n').expect(rc={1, 2}, out=r"unknown finger 'pinky'.*thumb, index")
    status(t, SOURCE + '[haptics]\nleft = ["index", "index"]\n').expect(rc={1, 2}, out=r"'index' listed twice")
    status(t, SOURCE + '[haptics]\ndevices = "emulated"\n').expect(rc={1, 2}, out=r"lists no fingers")


@case("29 [haptics] devices = \"usb\", an unknown key, a force scale of 100: refused with the choices / key / range")
def _(t):
    status(t, SOURCE + HAPTICS.replace('"emulated"', '"usb"')).expect(rc={1, 2}, out=r"emulated, hid")
    status(t, SOURCE + HAPTICS + 'gain = 2\n').expect(rc={1, 2}, out=r"gain")
    status(t, SOURCE + HAPTICS + 'force_scale = 100\n').expect(rc={1, 2}, out=r"layer.toml.*force_scale")
    status(t, SOURCE + HAPTICS + 'force_scale = nan\n').expect(rc={1, 2}, out=r"force_scale")


@case("29 emulated devices without a model: refused, an example given")
def _(t):
    status(t, SOURCE + HAPTICS + 'model = ""\n').expect(rc={1, 2}, out=r"need a device model.*platform_3dof")


@case("29 a device model that is a FIFO: no fingertip devices, said with the file, and the app runs on")
def _(t):
    fifo = t.fifo("model.toml")
    probe(t, SOURCE + HAPTICS + 'model = "' + str(fifo) + '"\n').expect(rc=0, err=r"no fingertip haptics.*model.toml.*FIFO")


@case("29 a device model of /dev/zero, or a broken one: refused as a character device / with the file and line")
def _(t):
    probe(t, SOURCE + HAPTICS + 'model = "/dev/zero"\n').expect(rc=0, err=r"no fingertip haptics.*/dev/zero.*character device")
    bad = t.write("bad_model.toml", 'kind = "platform_3dof"\n[limits\nmax_normal_n = \n')
    probe(t, SOURCE + HAPTICS + 'model = "' + str(bad) + '"\n').expect(rc=0, err=r"no fingertip haptics.*bad_model.toml:\d+")


def haptics_probe(t, config):
    return t.run("xr-probe", "--haptics", env=t.layer_env(config), timeout=90)


@case("29 xr-probe --haptics without a [haptics] table: exit 2, the table named")
def _(t):
    haptics_probe(t, SOURCE).expect(rc=2, err=r"no fingertip devices.*\[haptics\] table")


@case("29 xr-probe --haptics whose device model is a FIFO: exit 1, the layer's reason in its log")
def _(t):
    fifo = t.fifo("model.toml")
    haptics_probe(t, SOURCE + HAPTICS + 'model = "' + str(fifo) + '"\n').expect(
        rc=1, err=r"model.toml.*FIFO(.|\n)*xrCreateFingertipHapticsPROPRIO: XR_ERROR_FEATURE_UNSUPPORTED")


@case("29 xr-probe --haptics without Proprio's layer: exit 2, how to enable it")
def _(t):
    env = t.layer_env(SOURCE + HAPTICS)
    env["XR_ENABLE_API_LAYERS"] = ""
    t.run("xr-probe", "--haptics", env=env, timeout=90).expect(rc=2, err=r"XR_PROPRIO_fingertip_haptics is not offered")


@case("29 xr-probe --haptics with a [haptics] table the layer refused: exit 2, the layer's reason and the refusal said")
def _(t):
    haptics_probe(t, SOURCE + '[haptics]\ndevices = "emulated"\nright = ["pinky"]\n').expect(
        rc=2, err=r"unknown finger 'pinky'(.|\n)*no fingertip devices.*one it refused")


@case("29 xr-probe --haptics with a device model that does not exist: exit 1, the file named")
def _(t):
    haptics_probe(t, SOURCE + HAPTICS + 'model = "no_such_model"\n').expect(
        rc=1, err=r"no_such_model\.toml' does not exist(.|\n)*xrCreateFingertipHapticsPROPRIO: XR_ERROR_FEATURE_UNSUPPORTED")


@case("29 xr-probe --haptics on a session that is never FOCUSED: exit 1 after its wait, focus named, no press")
def _(t):
    env = t.layer_env(SOURCE + HAPTICS, {"PROPRIO_MOCK_RUNTIME_UNFOCUS_AFTER_FRAMES": "0"})
    t.run("xr-probe", "--haptics", env=env, timeout=90).expect(
        rc=1, err=r"did not become FOCUSED within 5 s.*XR_SESSION_STATE_VISIBLE", out=r"^(?!.*commanded).*$")


@case("29 xr-probe --haptics losing focus during the presses: exit 1, said, not reported as a device fault")
def _(t):
    config = SOURCE + '[haptics]\ndevices = "emulated"\nleft = ["thumb", "index", "middle"]\nright = ["index"]\n'
    env = t.layer_env(config, {"PROPRIO_MOCK_RUNTIME_UNFOCUS_AFTER_FRAMES": "150"})
    t.run("xr-probe", "--haptics", env=env, timeout=90).expect(
        rc=1, err=r"lost input focus during the presses.*XR_SESSION_STATE_VISIBLE", no_err=r"FAILED")
