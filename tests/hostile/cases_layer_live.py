"""Live gloves in the OpenXR layer (issue 26): the wrist from the runtime
(wrist = controller | tracker | runtime_hand, wrist_calibration files,
tracker roles), live and emulated VIST inputs, emulated gloves' truth files.
A bad value stops the config with the file, line and the allowed choices; a
hostile file named by a source fails that source, named, and the app runs on
(docs/openxr-layer.md)."""

from hostile import case



def status(t, config):
    return t.layer_status(config)


def xr_env(t, config, extra=None):
    return t.layer_env(config, extra)


def probe(t, config, extra=None, seconds="1"):
    return t.run("xr-probe", "--seconds", seconds, "--hand", "right", "--space", "local", env=xr_env(t, config, extra),
                 timeout=90)


NO_HANDS = {2, 3}
SIM = '[[source]]\ntype = "sim"\nhands = ["right"]\nspace = "local"\n'


@case("26 wrist = \"elbow\": refused with the four choices")
def _(t):
    status(t, SIM + 'wrist = "elbow"\n').expect(
        rc={1, 2}, out=r"'wrist' = \"elbow\" is not one of: source, controller, tracker, runtime_hand")


@case("26 a wrist offset without a controller or tracker wrist: refused, the key named")
def _(t):
    status(t, SIM + 'wrist_offset_position_m = [0, 0, 0.1]\n').expect(
        rc={1, 2}, out=r"'wrist_offset_position_m' applies only to wrist = \"controller\" or \"tracker\"")


@case("26 a wrist offset of NaN or 5 m: refused with the file and line")
def _(t):
    status(t, SIM + 'wrist = "tracker"\nwrist_offset_position_m = [nan, 0, 0]\n').expect(
        rc={1, 2}, out=r"layer.toml:\d+.*wrist_offset_position_m")
    status(t, SIM + 'wrist = "tracker"\nwrist_offset_position_m = [5, 0, 0]\n').expect(
        rc={1, 2}, out=r"layer.toml:\d+.*'wrist_offset_position_m' has 5")


@case("26 a tracker role with a path in it: refused")
def _(t):
    status(t, SIM + 'wrist = "tracker"\ntracker_role_right = "../../user/hand/right"\n').expect(
        rc={1, 2}, out=r"'tracker_role_right' = \"\.\./\.\./user/hand/right\" is not a tracker role")


@case("26 both a wrist calibration and an inline offset: refused")
def _(t):
    status(t, SIM + 'wrist = "tracker"\nwrist_calibration = "w.toml"\nwrist_offset_position_m = [0, 0, 0]\n').expect(
        rc={1, 2}, out=r"give either 'wrist_calibration' or the inline wrist offset")


@case("26 a live vist source bound to the view space: refused, the reason given")
def _(t):
    status(t, '[[source]]\ntype = "vist"\ninput = "device"\nspace = "view"\n').expect(
        rc={1, 2}, out=r"set space = \"local\" or \"stage\", not \"view\"")


@case("26 a vist key for another input (camera on a replay): refused, the input named")
def _(t):
    status(t, '[[source]]\ntype = "vist"\npath = "s.prec"\ncamera = "/dev/video0"\n').expect(
        rc={1, 2}, out=r"'camera' does not apply to input = \"replay\"")


@case("26 truth_path on a glove that is not emulated: refused")
def _(t):
    status(t, '[[source]]\ntype = "glove"\ninput = "sim"\ntruth_path = "t.csv"\n').expect(
        rc={1, 2}, out=r"'truth_path' applies only to input = \"emulated\"")


@case("26 wrist_calibration is a FIFO: the source is refused, named, and the app runs on without a hang")
def _(t):
    fifo = t.fifo("wrist.toml")
    r = probe(t, SIM + 'wrist = "tracker"\nwrist_calibration = "' + str(fifo) + '"\n')
    r.expect(rc=NO_HANDS, err=r"wrist.toml.*FIFO")


@case("26 wrist_calibration is /dev/zero, or has NaN: refused with the file and key")
def _(t):
    r = probe(t, SIM + 'wrist = "tracker"\nwrist_calibration = "/dev/zero"\n')
    r.expect(rc=NO_HANDS, err=r"/dev/zero")
    cal = t.write("w.toml", "[wrist]\nposition_m = [0, nan, 0]\nrotation_deg = [0, 0, 0]\n")
    r = probe(t, SIM + 'wrist = "tracker"\nwrist_calibration = "' + str(cal) + '"\n')
    r.expect(rc=NO_HANDS, err=r"w.toml.*position_m")


@case("26 wrist = tracker on a runtime with no trackers: the app runs, the hand is never active")
def _(t):
    r = probe(t, SIM + 'wrist = "tracker"\n', {"PROPRIO_MOCK_RUNTIME_TRACKERS": "0"}, seconds="2")
    r.expect(rc=3)


@case("26 wrist = runtime_hand on a runtime without hand tracking: said so, the source's own wrist serves")
def _(t):
    r = probe(t, SIM + 'wrist = "runtime_hand"\n')
    r.expect(rc=0, err=r"no hand tracking of its own", out=r"right\s+active in [1-9]\d* of ")


@case("26 an emulated glove whose truth_path is a folder: the source is refused, named")
def _(t):
    t.path("truth").mkdir()
    r = probe(t, '[[source]]\ntype = "glove"\ninput = "emulated"\nhands = ["right"]\nspace = "local"\n'
                 'truth_path = "' + str(t.path("truth")) + '"\n')
    r.expect(rc=NO_HANDS, err=r"truth")


@case("26 unplug_s with an odd count, a negative time or NaN: refused, the key named")
def _(t):
    glove = '[[source]]\ntype = "glove"\ninput = "emulated"\n'
    status(t, glove + 'unplug_s = [1.0]\n').expect(rc={1, 2}, out=r"'unplug_s' takes pairs")
    status(t, glove + 'unplug_s = [-1.0, 1.0]\n').expect(rc={1, 2}, out=r"'unplug_s' pair 1 needs")
    status(t, glove + 'unplug_s = [1.0, nan]\n').expect(rc={1, 2}, out=r"layer.toml:4:\d+: element 1 of .*unplug_s.* must be a finite number")
    status(t, '[[source]]\ntype = "glove"\ninput = "sim"\nunplug_s = [1.0, 1.0]\n').expect(
        rc={1, 2}, out=r"'unplug_s' applies only to input = \"emulated\"")


@case("26 a live vist camera that is a FIFO: refused at start, named; /dev/zero: named, retried, no hang")
def _(t):
    fifo = t.fifo("camera.avi")
    r = probe(t, '[[source]]\ntype = "vist"\ninput = "device"\nspace = "local"\nhands = ["right"]\n'
                 'camera = "' + str(fifo) + '"\n')
    r.expect(rc=NO_HANDS, err=r"vist source: .*camera.avi")
    r = probe(t, '[[source]]\ntype = "vist"\ninput = "device"\nspace = "local"\nhands = ["right"]\n'
                 'camera = "/dev/zero"\n')
    r.expect(rc=3, err=r"cannot open camera /dev/zero: .*trying again every 1 s")


@case("26 a live vist source with no board and no camera: the app runs, the hand never appears")
def _(t):
    r = probe(t, '[[source]]\ntype = "vist"\ninput = "device"\nspace = "local"\nhands = ["right"]\n'
                 'camera = "/dev/video97"\nimu_path = "/dev/hidraw97"\n', seconds="2")
    r.expect(rc=3)


@case("26 an emulated vist glove with its board unplugged for good: the app runs on, the hand goes away")
def _(t):
    r = probe(t, '[[source]]\ntype = "vist"\ninput = "emulated"\nspace = "local"\nhands = ["right"]\n'
                 'unplug_s = [0.0, 3600]\n', seconds="2")
    r.expect(rc=3)


@case("26 a glove source given two hands: refused, named, the app runs on")
def _(t):
    r = probe(t, '[[source]]\ntype = "glove"\ninput = "emulated"\nhands = ["left", "right"]\n')
    r.expect(rc=NO_HANDS, err=r"glove source: .*a glove source is one glove")
