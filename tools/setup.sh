# Sourced by tools/test.sh and .ci/run: installs what a fresh Debian/Ubuntu
# machine lacks for the tests (as root; otherwise says the one command to
# run) and sets the environment wgpu needs.
#
# - mesa-vulkan-drivers, libvulkan1: Mesa's lavapipe (software Vulkan). The
#   programs also run on wgpu's OpenGL backend (llvmpipe), but the tests
#   compare the two backends.
# - xvfb, xauth and the X11 libraries winit loads at run time, and a font:
#   the window presenter's tests run under a virtual X server (xdotool
#   drives the interactive one with synthetic mouse and keys); the overlay
#   and the eval plots draw text.
# - g++: nv-flip (the ꟻLIP metric) builds NVIDIA's C++ FLIP.
# - libavcodec-dev, libavformat-dev (FFmpeg 5.1 with libx264), clang,
#   libclang-dev, pkg-config: the `video` crate codes colour as H.264
#   through ffmpeg-next, whose bindings bindgen generates from the installed
#   headers (ffmpeg-next's build instructions list clang beside
#   libclang-dev; the build CI verified had both).
packages="mesa-vulkan-drivers libvulkan1 xvfb xauth xdotool libx11-6 libxcursor1 libxrandr2 libxi6 libxkbcommon-x11-0 fonts-dejavu-core g++ libavcodec-dev libavformat-dev clang libclang-dev pkg-config"
# shellcheck disable=SC2086
if ! dpkg -s $packages >/dev/null 2>&1; then
  if [ "$(id -u)" = 0 ]; then
    echo "== installing: $packages"
    export DEBIAN_FRONTEND=noninteractive
    apt-get update -qq
    # shellcheck disable=SC2086
    apt-get install -y -qq $packages >/dev/null
  else
    # shellcheck disable=SC2086
    missing=$(for p in $packages; do dpkg -s "$p" >/dev/null 2>&1 || printf '%s ' "$p"; done)
    echo "error: missing packages; install them with: sudo apt-get install -y ${missing% }" >&2
    exit 1
  fi
fi
# Pin wgpu's Vulkan loader to lavapipe where it is the driver installed.
lavapipe=/usr/share/vulkan/icd.d/lvp_icd.x86_64.json
if [ -z "${VK_DRIVER_FILES:-}" ] && [ -f "$lavapipe" ]; then
  export VK_DRIVER_FILES="$lavapipe"
fi
export XDG_RUNTIME_DIR="${XDG_RUNTIME_DIR:-/tmp/xdg-runtime-$(id -u)}"
mkdir -p "$XDG_RUNTIME_DIR" && chmod 0700 "$XDG_RUNTIME_DIR"
