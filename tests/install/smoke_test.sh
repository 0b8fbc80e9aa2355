#!/usr/bin/env bash
# Smoke test of an installed Proprio: `cmake --install` to any prefix, the .deb
# installed with apt, or the .deb unpacked with `dpkg -x` (docs/install.md).
#
#   tests/install/smoke_test.sh --prefix PREFIX --mock-runtime-json JSON [--version X.Y.Z] [--hide DIR]...
#
#   --prefix             the installed prefix: /usr for the .deb, <root>/usr for `dpkg -x`
#   --mock-runtime-json  the project's mock OpenXR runtime (build/<preset>/tests/openxr/mock_runtime/
#                        mock_runtime.json); copied with its library, so it may be hidden by --hide
#   --version            the version `proprio --version` must print
#   --hide DIR           make DIR (the source and build trees) invisible to the installed
#                        programs, in a private mount namespace, so that a path baked at
#                        build time cannot pass unnoticed; skipped, and said so, where
#                        mount namespaces are not allowed
#
# Checks: the files are where docs/install.md says; `proprio --version`; a
# command that reads the shipped data (`haptics sim`); `proprio
# layer status` reports the installed layer through the installed manifest and the
# OpenXR loader's own search path; `proprio xr-probe` on the mock runtime gets
# hands from the installed layer (LD_DEBUG shows which library the loader
# opened); `proprio xr-probe --haptics` presses an emulated fingertip device
# through the installed haptics plugin and its installed model. Exits non-zero
# on the first failure.
set -euo pipefail

prefix="" runtime_json="" version="" hide=()
while [ $# -gt 0 ]; do
  case $1 in
    --prefix) prefix=$2; shift 2 ;;
    --mock-runtime-json) runtime_json=$2; shift 2 ;;
    --version) version=$2; shift 2 ;;
    --hide) hide+=("$2"); shift 2 ;;
    --in-namespace) in_namespace=1; shift ;;
    *) echo "smoke_test.sh: unknown option '$1' (see the comment at the top of $0)" >&2; exit 2 ;;
  esac
done
[ -n "$prefix" ] && [ -n "$runtime_json" ] ||
  { echo "smoke_test.sh: --prefix and --mock-runtime-json are required" >&2; exit 2; }
prefix=$(cd "$prefix" && pwd)

fail() { printf 'install smoke test FAILED: %s\n' "$*" >&2; exit 1; }
ok() { printf '  ok  %s\n' "$*"; }

# Re-run this script in a private mount namespace with the trees hidden.
if [ ${#hide[@]} -gt 0 ] && [ -z "${in_namespace:-}" ]; then
  work=$(mktemp -d /tmp/proprio-install-smoke.XXXXXX)
  trap 'rm -rf "$work"' EXIT
  # The mock runtime lives in the build tree: copy it out before hiding that.
  runtime_lib=$(python3 -c 'import json,sys,os; p=json.load(open(sys.argv[1]))["runtime"]["library_path"]; print(p if os.path.isabs(p) else os.path.join(os.path.dirname(sys.argv[1]), p))' "$runtime_json")
  cp "$runtime_lib" "$work/"
  python3 -c 'import json,sys; j=json.load(open(sys.argv[1])); j["runtime"]["library_path"]=sys.argv[2]; json.dump(j, open(sys.argv[3], "w"))' \
    "$runtime_json" "$work/$(basename "$runtime_lib")" "$work/mock_runtime.json"
  cp "$0" "$work/smoke_test.sh"
  if unshare -m true 2>/dev/null; then
    mounts=""
    for d in "${hide[@]}"; do mounts+="mount -t tmpfs -o size=1m proprio-hidden '$d' && "; done
    echo "Hiding ${hide[*]} from the installed programs (private mount namespace)"
    # shellcheck disable=SC2016
    unshare -m bash -c "mount --make-rprivate / && ${mounts} exec bash '$work/smoke_test.sh' --in-namespace \
      --prefix '$prefix' --mock-runtime-json '$work/mock_runtime.json' ${version:+--version '$version'}"
    exit $?
  fi
  echo "Note: no mount namespace here (needs root or CAP_SYS_ADMIN), so ${hide[*]} stay visible;" \
       "a path baked at build time would go unnoticed"
  runtime_json=$work/mock_runtime.json
fi

cli=$prefix/bin/proprio
manifest_dir=$prefix/share/openxr/1/api_layers/explicit.d
manifest=$manifest_dir/XrApiLayer_proprio_hand_tracking.json
tmp=$(mktemp -d /tmp/proprio-install-run.XXXXXX)
trap 'rm -rf "$tmp"' EXIT
cd "$tmp"

# Only what an installed system would see: no user manifests or configs of the
# person running this, no data override, the manifest found through the
# loader's XDG_DATA_DIRS search (for /usr that is the loader's default).
export HOME=$tmp/home
mkdir -p "$HOME"
unset XDG_DATA_HOME XDG_CONFIG_HOME XDG_CONFIG_DIRS XR_API_LAYER_PATH PROPRIO_DATA_DIR PROPRIO_LAYER_CONFIG \
  DISABLE_XR_APILAYER_PROPRIO_HAND_TRACKING XR_ENABLE_API_LAYERS XR_RUNTIME_JSON
case $prefix in
  /usr | /usr/local) unset XDG_DATA_DIRS ;;
  *) export XDG_DATA_DIRS=$prefix/share ;;
esac
echo "Installed prefix: $prefix"

# --- files
[ -x "$cli" ] || fail "$cli is missing or not executable"
[ -f "$manifest" ] || fail "the layer manifest $manifest is missing"
library_path=$(python3 -c 'import json,sys; print(json.load(open(sys.argv[1]))["api_layer"]["library_path"])' "$manifest")
case $library_path in /*) layer_lib=$library_path ;; *) layer_lib=$manifest_dir/$library_path ;; esac
[ -f "$layer_lib" ] || fail "the manifest's library_path $library_path resolves to $layer_lib, which does not exist"
layer_lib=$(readlink -f "$layer_lib")
ok "layer manifest $manifest -> $layer_lib"
[ -f "$prefix/share/proprio/vist_glove.toml" ] && [ -f "$prefix/share/proprio/models/stretch_glove_generic.onnx" ] ||
  fail "the data folder $prefix/share/proprio is missing or incomplete"
ok "data folder $prefix/share/proprio"
[ -f "$prefix/include/proprio/core/hand_pose.hpp" ] || fail "the headers are not under $prefix/include/proprio"
ok "headers $prefix/include/proprio"

# --- proprio --version
out=$("$cli" --version) || fail "proprio --version exited $?"
echo "$out" | sed 's/^/    /'
if [ -n "$version" ]; then
  grep -q -- "$version" <<<"$out" || fail "proprio --version does not print $version"
fi
ok "proprio --version"

# --- the shipped data, found from the installed binaries (a helper program in
# libexec/ here: `haptics sim` loads the default device model, band_2dof.toml)
out=$("$cli" haptics sim --scene half-cylinder --seconds 0.2 2>&1) ||
  { echo "$out" >&2; fail "proprio haptics sim (reads the installed device model) exited non-zero"; }
grep -q "band_2dof" <<<"$out" || { echo "$out" >&2; fail "proprio haptics sim did not use the shipped band_2dof model"; }
ok "proprio haptics sim: the shipped device model from $prefix/share/proprio"

# --- proprio layer status
"$cli" layer init-config --out "$tmp/layer.toml" >/dev/null || fail "proprio layer init-config exited $?"
export PROPRIO_LAYER_CONFIG=$tmp/layer.toml XR_RUNTIME_JSON=$runtime_json
export XR_ENABLE_API_LAYERS=XR_APILAYER_PROPRIO_hand_tracking
set +e
status=$("$cli" layer status 2>&1)
rc=$?
set -e
echo "$status" | sed 's/^/    /'
[ $rc -eq 0 ] || fail "proprio layer status exited $rc (0: the layer would load and can serve hands)"
grep -qF "This installation's layer library: $layer_lib" <<<"$status" ||
  fail "proprio layer status does not name the installed layer $layer_lib as its own"
grep -qF "$manifest" <<<"$status" || fail "proprio layer status does not list the installed manifest $manifest"
grep -q "library_path $library_path: OK" <<<"$status" || fail "proprio layer status does not find the installed library usable"
ok "proprio layer status: the installed layer, found by the loader's search, would load"

# --- proprio xr-probe on the mock runtime, through the installed manifest
# LD_DEBUG=files logs every library the process opens: the layer the loader
# picked must be the installed one (the loader's own log does not name it).
set +e
probe=$(LD_DEBUG=files "$cli" xr-probe --seconds 1 --space view 2>&1)
rc=$?
set -e
grep -vE '^ *[0-9]+:' <<<"$probe" | sed 's/^/    /' || true
[ $rc -eq 0 ] || { grep -vE '^ *[0-9]+:' <<<"$probe" | tail -40 >&2; fail "proprio xr-probe exited $rc"; }
grep -q "Proprio layer: serving XR_EXT_hand_tracking" <<<"$probe" || fail "the layer did not start serving hands"
grep -qE "^t= *[0-9.]+ s (left|right) +active" <<<"$probe" || fail "xr-probe located no active hand"
loaded=$(grep -oE 'file=[^ ]*libXrApiLayer_proprio_hand_tracking\.so' <<<"$probe" | head -1 | sed 's/^file=//')
[ -n "$loaded" ] || fail "no Proprio layer library was loaded"
[ "$(readlink -f "$loaded")" = "$layer_lib" ] || fail "the loader loaded $loaded, not the installed $layer_lib"
ok "proprio xr-probe: hands from the installed layer ($loaded) on the mock runtime"

# --- fingertip haptics from the installed haptics plugin and its installed device model
cat "$tmp/layer.toml" >"$tmp/layer_haptics.toml"
printf '\n[haptics]\ndevices = "emulated"\nmodel = "platform_3dof"\nright = ["index"]\n' >>"$tmp/layer_haptics.toml"
set +e
haptics=$(LD_DEBUG=files PROPRIO_LAYER_CONFIG=$tmp/layer_haptics.toml "$cli" xr-probe --haptics 2>&1)
rc=$?
set -e
grep -vE '^ *[0-9]+:' <<<"$haptics" | sed 's/^/    /' || true
[ $rc -eq 0 ] || fail "proprio xr-probe --haptics exited $rc"
plugin=$(grep -oE 'file=[^ ]*libproprio_source_haptics\.so' <<<"$haptics" | head -1 | sed 's/^file=//')
[ -n "$plugin" ] || fail "the layer loaded no haptics plugin"
case $(readlink -f "$plugin") in
  "$prefix"/*) ;;
  *) fail "the layer loaded the haptics plugin $plugin, not the installed one under $prefix" ;;
esac
grep -q "right index  commanded" <<<"$haptics" || fail "xr-probe --haptics pressed no right index"
ok "proprio xr-probe --haptics: the installed haptics plugin ($plugin) pressed an emulated device"
echo "install smoke test passed ($prefix)"
