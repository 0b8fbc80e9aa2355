"""Stretch sensor array layouts (issue 30): `array check` and `array layout`
against special files, broken and hostile TOML, layouts whose strips cross
twice, and outputs that must not be overwritten (docs/stretch-arrays.md)."""
from hostile import case

STRIPS = '[[top_strip]]\nname = "1"\n[[bottom_strip]]\nname = "A"\n'
CELL = '[[cell]]\ntop = "1"\nbottom = "A"\n'


@case("30 array check on /dev/zero, a FIFO, a folder, a missing file: refused at once, named")
def _(t):
    t.run("array", "check", "/dev/zero", timeout=20).fails_cleanly(r"/dev/zero.*character device")
    fifo = t.fifo("layout.toml")
    t.run("array", "check", fifo, timeout=20).fails_cleanly(r"layout.toml.*FIFO")
    t.path("folder").mkdir()
    t.run("array", "check", t.path("folder"), timeout=20).fails_cleanly(r"folder")
    t.run("array", "check", "missing.toml", timeout=20).fails_cleanly(r"missing.toml")


@case("30 array check on broken TOML, binary bytes, a huge file: refused with the file")
def _(t):
    t.run("array", "check", t.write("broken.toml", "[[top_strip]\nname = \n")).fails_cleanly(r"broken.toml:\d+")
    t.run("array", "check", t.write("binary.toml", bytes(range(256)) * 16)).fails_cleanly(r"binary.toml")
    t.run("array", "check", t.write("huge.toml", "# " + "x" * (5 * 1024 * 1024) + "\n"), timeout=30).fails_cleanly(
        r"huge.toml.*(too large|bigger|MiB|bytes)")


@case("30 array check: strips crossing twice, an unknown strip, nan sizes, a self-crossing outline: refused, named")
def _(t):
    twice = STRIPS + CELL + '[[cell]]\nname = "again"\ntop = "1"\nbottom = "A"\n'
    t.run("array", "check", t.write("twice.toml", twice)).fails_cleanly(r"cross twice")
    t.run("array", "check", t.write("unknown.toml", STRIPS + '[[cell]]\ntop = "9"\nbottom = "A"\n')).fails_cleanly(
        r"unknown.toml:\d+.*no top strip named '9'")
    nan = STRIPS.replace('name = "1"\n', 'name = "1"\nwidth_m = nan\n') + CELL
    t.run("array", "check", t.write("nan.toml", nan)).fails_cleanly(r"nan.toml.*width_m")
    bow = STRIPS + CELL + 'outline_m = [0, 0, 0.004, 0.004, 0.004, 0, 0, 0.004]\n'
    t.run("array", "check", t.write("bow.toml", bow)).fails_cleanly(r"crosses itself")


@case("30 array layout --out over an existing file without --force: refused, the file unchanged")
def _(t):
    t.write("mine.toml", "name = \"mine\"\n")
    t.watch("mine.toml")
    t.run("array", "layout", "--out", "mine.toml").fails_cleanly(r"mine.toml.*exists")
    t.unchanged()
    t.path("dir").mkdir()
    t.run("array", "layout", "--out", t.path("dir")).fails_cleanly(r"dir")
    t.run("array", "layout", "--example", "nope").fails_cleanly(r"nope")
