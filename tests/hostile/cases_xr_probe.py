"""`proprio xr-probe` on runtimes that behave differently (issue 24): the mock
OpenXR runtime as it is (headless frames work) and switched to behave as Monado
does (PROPRIO_MOCK_RUNTIME_MONADO_HEADLESS=1: xrBeginFrame refused in headless
sessions), through the loader with Proprio's layer serving simulated hands.
Checks which session path the probe took, that it sees hands, and its exit
statuses (0 hands, 1 any failed call, 2 no hand tracking, 3 never active)."""
from pathlib import Path

from hostile import case

LAYER = "XR_APILAYER_PROPRIO_hand_tracking"
# Mesa's lavapipe: the Vulkan session runs on the CPU.
LAVAPIPE_ICD = Path("/usr/share/vulkan/icd.d/lvp_icd.x86_64.json")

SIM_CONFIG = """[layer]
runtime_hand_tracking = "auto"

[[source]]
type = "sim"
hands = {hands}
space = "view"
"""


def xr_env(t, monado=False, layer=True, hands='["left", "right"]'):
    """The loader pointed at the mock runtime, with Proprio's layer enabled
    from the build folder and a simulated-hand config."""
    t.need(bool(t.opts.mock_runtime_json) and Path(t.opts.mock_runtime_json).exists(),
           "no mock OpenXR runtime manifest (--mock-runtime-json)")
    env = {"XR_RUNTIME_JSON": str(Path(t.opts.mock_runtime_json).resolve())}
    if layer:
        t.need(bool(t.opts.layer_dir) and Path(t.opts.layer_dir).is_dir(), "no built layer (--layer-dir)")
        env["XR_API_LAYER_PATH"] = str(Path(t.opts.layer_dir).resolve())
        env["XR_ENABLE_API_LAYERS"] = LAYER
        env["PROPRIO_LAYER_CONFIG"] = str(t.write("layer.toml", SIM_CONFIG.format(hands=hands)))
    if monado:
        env["PROPRIO_MOCK_RUNTIME_MONADO_HEADLESS"] = "1"
    return env


def need_lavapipe(t):
    t.need(LAVAPIPE_ICD.exists(), f"no lavapipe Vulkan driver ({LAVAPIPE_ICD}; Debian: mesa-vulkan-drivers)")


HANDS_ACTIVE = r"left\s+active in [1-9]\d* of .*right\s+active in [1-9]\d* of "


@case("24.2 plain mock runtime: xr-probe runs headless and sees both hands")
def _(t):
    r = t.run("xr-probe", "--seconds", "1.5", env=xr_env(t), timeout=60)
    r.expect(rc=0, out=r"Session: headless \(XR_MND_headless\)")
    r.expect(out=r"frames, headless session:" + r".*" + HANDS_ACTIVE, no_err=r"error")
    assert "Vulkan" not in r.out, "the probe left the headless path on a runtime that runs headless frames\n" + \
        r.describe()


@case("24.2 Monado-like runtime: xr-probe says headless frames are refused and falls back to Vulkan")
def _(t):
    need_lavapipe(t)
    r = t.run("xr-probe", "--seconds", "1.5", env=xr_env(t, monado=True), timeout=90)
    r.expect(rc=0, out=r"refuses frames in headless sessions \(xrBeginFrame: XR_ERROR_CALL_ORDER_INVALID\)")
    r.expect(out=r"Session: Vulkan graphics binding \(XR_KHR_vulkan_enable2\) on ")
    r.expect(out=r"frames, Vulkan session:" + r".*" + HANDS_ACTIVE)
    # The refused frame is expected there: it is not reported as an error.
    r.expect(no_err=r"\berror\b")


@case("24.2 --session vulkan on the plain mock runtime: Vulkan session, hands seen")
def _(t):
    need_lavapipe(t)
    r = t.run("xr-probe", "--seconds", "1.5", "--session", "vulkan", env=xr_env(t), timeout=90)
    r.expect(rc=0, out=r"Session: Vulkan graphics binding .*frames, Vulkan session:.*" + HANDS_ACTIVE)
    assert "refuses" not in r.out, r.describe()


@case("24.2 Monado-like runtime, --session headless: the failed xrBeginFrame exits 1, not 3")
def _(t):
    r = t.run("xr-probe", "--seconds", "1.5", "--session", "headless", env=xr_env(t, monado=True), timeout=60)
    r.fails_cleanly(r"refuses frames in headless sessions \(xrBeginFrame: XR_ERROR_CALL_ORDER_INVALID\).*"
                    r"--session vulkan")
    assert "No hand was ever active" not in r.out, "a failed call was reported as 'no hand active'\n" + r.describe()


@case("24.2 no Vulkan driver: the fallback fails with exit 1 and says why")
def _(t):
    env = xr_env(t, monado=True)
    t.write("no_driver.json", "")
    env["VK_ICD_FILENAMES"] = str(t.path("no_driver.json"))  # Vulkan loader: only this (unusable) driver
    r = t.run("xr-probe", "--seconds", "1", env=env, timeout=60)
    r.fails_cleanly(r"Vulkan graphics binding could not be set up: .*(vkCreateInstance|device)")


@case("24.2 no layer: XR_EXT_hand_tracking not offered exits 2")
def _(t):
    r = t.run("xr-probe", "--seconds", "1", env=xr_env(t, layer=False), timeout=60)
    r.expect(rc=2, err=r"XR_EXT_hand_tracking is not offered")


@case("24.2 a hand with no source is never active: exit 3, every call succeeded")
def _(t):
    r = t.run("xr-probe", "--seconds", "1", "--hand", "left", env=xr_env(t, hands='["right"]'), timeout=60)
    r.expect(rc=3, out=r"left\s+active in 0 of [1-9]\d* locates.*No hand was ever active", no_err=r"failed")


@case("24.2 the Vulkan fallback, under Debian's core_validation layer, raises no validation error")
def _(t):
    need_lavapipe(t)
    explicit = Path("/usr/share/openxr/1/api_layers/explicit.d")
    t.need(any(explicit.glob("*core_validation*.json")), "openxr-layer-corevalidation is not installed")
    env = xr_env(t, monado=True)
    report = t.path("core_validation.txt")
    env.update({"XR_API_LAYER_PATH": f"{explicit}:{env['XR_API_LAYER_PATH']}",
                "XR_ENABLE_API_LAYERS": f"XR_APILAYER_LUNARG_core_validation:{LAYER}",
                "XR_CORE_VALIDATION_EXPORT_TYPE": "text", "XR_CORE_VALIDATION_FILE_NAME": str(report)})
    r = t.run("xr-probe", "--seconds", "1", env=env, timeout=90)
    r.expect(rc=0, out=r"Session: Vulkan graphics binding.*frames, Vulkan session:.*" + HANDS_ACTIVE)
    # The layer writes the file only when it has something to report.
    found = report.read_text(errors="replace") if report.exists() else ""
    assert "VALID_ERROR" not in found, "core_validation reported:\n" + found[:3000]
