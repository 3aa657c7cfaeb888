#!/bin/bash
# Device run of the compact-distributions GPU reports, from a frozen snapshot.
# Called from the repo root on the device as:
#   set -o pipefail; bash .gpu/run.sh 2>&1 | tee $OUT/log
# Carries: .gpu (snapshot source, its wheel, this script), .whl (cp312 wheels), .gl (GL debs).
# LOCAL_TEST=1 skips the dpkg step (for a dry run on a machine without the GPU); PY picks python.
set -u
export PYTHONUNBUFFERED=1
PY=${PY:-python3}
OUT=${OUT:?OUT unset}
ROOT=$(pwd)
LOCAL_TEST=${LOCAL_TEST:-0}
T0=$(date +%s)
DEADLINE=${DEADLINE:-390}   # seconds after start by which the script must be done (run timeout 420)
left() { echo $(( DEADLINE - ($(date +%s) - T0) )); }
stamp() { echo; echo "=== [$(( $(date +%s) - T0 )) s] $*"; }
mkdir -p "$OUT"

stamp "host"
uname -a; $PY --version; nproc; free -g 2>/dev/null | head -2
echo "snapshot commit: $(cat .gpu/src/SNAPSHOT_COMMIT 2>/dev/null)"

stamp "GL debs (dpkg -x into /, ldconfig)"
if [ "$LOCAL_TEST" != 1 ]; then
  for f in .gl/*.deb; do dpkg -x "$f" /; done
  ldconfig
fi

stamp "pip install carried wheels into /tmp/site"
rm -rf /tmp/site
if ! $PY -m pip install -q --no-index --no-deps --no-compile --no-cache-dir --upgrade --target /tmp/site .whl/*.whl .gpu/whl/*.whl; then
  echo "FAILED: pip install of the carried wheels"; exit 3
fi
export PYTHONPATH=/tmp/site
$PY -m pip list 2>/dev/null | grep -iE "^(numpy|scipy|pandas|matplotlib|pillow|tqdm|typing.extensions|setuptools) " || true

stamp "NVIDIA OpenCL ICD"
OCLLIB=""
for d in /usr/local/nvidia/lib64 /usr/local/nvidia/lib /usr/lib/x86_64-linux-gnu /usr/lib64 /usr/lib; do
  for f in "$d"/libnvidia-opencl.so.1 "$d"/libnvidia-opencl.so*; do
    if [ -e "$f" ]; then OCLLIB=$f; break 2; fi
  done
done
if [ -z "$OCLLIB" ]; then
  OCLLIB=$(timeout 40 find /usr/local/nvidia /usr /lib /lib64 /opt -name 'libnvidia-opencl.so*' 2>/dev/null | head -1)
fi
echo "libnvidia-opencl: ${OCLLIB:-NOT FOUND}"
ls /etc/OpenCL/vendors 2>/dev/null && cat /etc/OpenCL/vendors/* 2>/dev/null
mkdir -p /tmp/icd
if [ -n "$OCLLIB" ]; then
  echo "$OCLLIB" > /tmp/icd/nvidia.icd
  export OCL_ICD_VENDORS=/tmp/icd
  export LD_LIBRARY_PATH="$(dirname "$OCLLIB")${LD_LIBRARY_PATH:+:$LD_LIBRARY_PATH}"
fi
ls /usr/local/nvidia/lib64 2>/dev/null | grep -iE "opencl|EGL|GLESv|GLX_nvidia|glcore|ptxjit" | tr '\n' ' '; echo

stamp "EGL vendor"
EGLJSON=/usr/local/nvidia/share/glvnd/egl_vendor.d/10_nvidia.json
if [ ! -e "$EGLJSON" ]; then
  EGLJSON=$(timeout 30 find /usr/local/nvidia /usr/share /etc -name '10_nvidia.json' 2>/dev/null | grep egl_vendor | head -1)
fi
echo "egl vendor json: ${EGLJSON:-NOT FOUND}"
if [ "$LOCAL_TEST" != 1 ] && [ -n "$EGLJSON" ]; then
  export __EGL_VENDOR_LIBRARY_FILENAMES=$EGLJSON
  cat "$EGLJSON"
fi

stamp "probe: nvidia-smi"
nvidia-smi || echo "nvidia-smi failed"
nvidia-smi --query-gpu=name,driver_version,memory.total,clocks.max.sm --format=csv || true

mkdir -p /tmp/run && cd /tmp/run   # away from the repo root's egg-info
CVT="$PY -m compact_distributions.bench.commands.cli"

stamp "probe: pyopencl platforms"
echo "OCL_ICD_VENDORS=${OCL_ICD_VENDORS:-} LD_LIBRARY_PATH=${LD_LIBRARY_PATH:-}"
timeout 90 $PY - <<'EOF' || echo "pyopencl probe failed (rc $?)"
import pyopencl as cl
for p in cl.get_platforms():
    print("platform:", p.name, "|", p.vendor, "|", p.version)
    for d in p.get_devices():
        print("  device:", d.name, "|", cl.device_type.to_string(d.type), "| driver", d.driver_version,
              "| CUs", d.max_compute_units, "| mem", d.global_mem_size // 2**20, "MiB")
EOF

stamp "probe: moderngl EGL"
timeout 90 $PY - <<'EOF' || echo "moderngl probe failed (rc $?)"
import moderngl
for req in (None, 430):
    try:
        ctx = moderngl.create_context(standalone=True, backend="egl", require=req)
    except Exception as exc:
        print("require", req, ": FAILED", exc); continue
    print("require", req, ":", " | ".join(ctx.info[k] for k in ("GL_VENDOR", "GL_RENDERER", "GL_VERSION")))
    ctx.release()
EOF

stamp "cvtbench info"
timeout 120 $CVT info 2>&1 | tee "$OUT/info.txt" || echo "cvtbench info failed (rc $?)"

stamp "cvtbench backends --quick"
BK=opencl,gl-cone,gl-exact,numpy,ckdtree
timeout 210 $CVT backends --quick --backends $BK --memory-limit 32G --quiet --out "$OUT/backends"
rc=$?; echo "backends rc=$rc"
if [ $rc -ne 0 ] && [ $(left) -gt 200 ]; then
  # a crash in one backend stops the whole sweep: find which run alone, then rebuild the
  # report from those (the sweep resumes from the raw json already written)
  OK=numpy,ckdtree
  for b in opencl gl-cone gl-exact; do
    stamp "retry backends alone: $b"
    if timeout 45 $CVT backends --quick --backends $b,numpy --memory-limit 32G --quiet --out "$OUT/backends_$b"; then
      OK=$OK,$b
    else
      echo "backend $b FAILED on its own (rc $?)"
    fi
  done
  stamp "backends again with $OK"
  timeout 45 $CVT backends --quick --backends $OK --memory-limit 32G --quiet --out "$OUT/backends"
  echo "backends (retry) rc=$?"
fi
cp "$OUT/backends/backends.md" "$OUT/" 2>/dev/null
tar -czf "$OUT/backends.tgz" -C "$OUT" $(cd "$OUT" && ls -d backends*/ 2>/dev/null) && rm -rf "$OUT"/backends/ "$OUT"/backends_*/

stamp "cvtbench pipeline --quick"
T=$(left); [ $T -gt 150 ] && T=150; [ $T -lt 20 ] && T=20
timeout $T $CVT pipeline --quick --backends opencl --memory-limit 32G --quiet --out "$OUT/pipeline"
rc=$?; echo "pipeline rc=$rc"
if { [ $rc -ne 0 ] || ! grep -q ',ok,' "$OUT/pipeline/pipeline.csv" 2>/dev/null; } && [ $(left) -gt 40 ]; then
  stamp "pipeline with opencl failed; numpy instead (CPU, marked as such)"
  timeout $(( $(left) - 10 )) $CVT pipeline --quick --backends numpy --memory-limit 32G --quiet --out "$OUT/pipeline_numpy"
  echo "pipeline numpy rc=$?"
fi
cp "$OUT/pipeline/pipeline.md" "$OUT/" 2>/dev/null
tar -czf "$OUT/pipeline.tgz" -C "$OUT" $(cd "$OUT" && ls -d pipeline*/ 2>/dev/null) && rm -rf "$OUT"/pipeline/ "$OUT"/pipeline_*/

stamp "done"
ls -la "$OUT"
