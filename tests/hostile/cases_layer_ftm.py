"""The FTM glove in the OpenXR layer (issue 27 §4): bad `ftm` keys stop the
config with the file and the allowed choices; a hostile calibration file
named by an ftm source fails that source, named, and the app runs on
(docs/openxr-layer.md)."""

from hostile import case



def ftm_status(t, config):
    return t.layer_status(config)


def ftm_probe(t, config):
    return t.run("xr-probe", "--seconds", "1", "--hand", "right", "--space", "local", env=t.layer_env(config), timeout=90)


FTM_NO_HANDS = {2, 3}
FTM = '[[source]]\ntype = "ftm"\nspace = "local"\n'


@case("27 an ftm source on two hands: refused, one glove per source")
def _(t):
    ftm_status(t, FTM + 'hands = ["left", "right"]\n').expect(rc={1, 2}, out=r"an ftm source is one glove")


@case("27 ftm input = \"usb\" and abduction = \"no\": refused with the choices / the key")
def _(t):
    ftm_status(t, FTM + 'input = "usb"\n').expect(rc={1, 2}, out=r"sim, emulated, device")
    ftm_status(t, FTM + 'abduction = "no"\n').expect(rc={1, 2}, out=r"layer.toml:\d+.*abduction")


@case("27 an ftm board without a calibration: refused, the command that writes one named")
def _(t):
    ftm_status(t, FTM + 'input = "device"\n').expect(rc={1, 2}, out=r"proprio calibrate ftm")


@case("27 a stretch-glove key on an ftm source (model): refused as unknown")
def _(t):
    ftm_status(t, FTM + 'model = "m.onnx"\n').expect(rc={1, 2}, out=r"model")


@case("27 ftm unplugs on a simulated wearer, subject on a board: refused, the input named")
def _(t):
    ftm_status(t, FTM + 'unplug_s = [1.0, 0.5]\n').expect(rc={1, 2}, out=r"'unplug_s' applies only to input = \"emulated\"")
    ftm_status(t, FTM + 'input = "device"\ncalibration = "c.toml"\nsubject = 2\n').expect(
        rc={1, 2}, out=r"'subject' applies only to a simulated wearer")


@case("27 an ftm calibration that is a FIFO: the source is refused, named, and the app runs on without a hang")
def _(t):
    fifo = t.fifo("ftm.toml")
    ftm_probe(t, FTM + 'calibration = "' + str(fifo) + '"\n').expect(rc=FTM_NO_HANDS, err=r"ftm.toml.*FIFO")


@case("27 an ftm calibration of /dev/zero: refused as a character device")
def _(t):
    ftm_probe(t, FTM + 'input = "device"\ncalibration = "/dev/zero"\n').expect(rc=FTM_NO_HANDS,
                                                                              err=r"/dev/zero.*character device")


@case("27 a broken ftm calibration file: the source is refused with the file and line")
def _(t):
    bad = t.write("ftm_cal.toml", "[ftm\nbeta1 = \n")
    ftm_probe(t, FTM + 'input = "emulated"\ncalibration = "' + str(bad) + '"\n').expect(
        rc=FTM_NO_HANDS, err=r"ftm_cal.toml:\d+")
