#!/usr/bin/env bash
# Build the MPEG-I Haptics reference software (ISO/IEC 23090-31, Release) and print the
# path of the executable that round-trips .hjif files:
#     <printed path> -f in.hjif -o out.hjif
# (Encoder: IOJson::loadFile -> in-memory model -> IOJson::writeFile). Its exit code is
# always 255 for .hjif input, even when loading fails: judge acceptance by an empty stderr.
#
# Usage: MIRROR=DIR scripts/build_mpeg_reference.sh [SNAPSHOT_GIT_DIR] [BUILD_DIR]
#   MIRROR            folder holding bare git clones <owner>+<name>/repo of the reference
#                     software and of the third-party sources below (git clone --bare
#                     https://github.com/<owner>/<name> "$MIRROR/<owner>+<name>/repo")
#   SNAPSHOT_GIT_DIR  bare git dir of MPEGGroup/HapticReferenceSoftware
#                     (default $MIRROR/MPEGGroup+HapticReferenceSoftware/repo)
#   BUILD_DIR         default <repo root>/build/mpeg-reference
# The tests that run the result find it through HCARD_MPEG_REFERENCE=<printed path>.
# Idempotent: re-running with an existing build for the same snapshot commit only prints the path.
set -euo pipefail

ROOT=$(cd "$(dirname "$0")/.." && pwd)
MIRROR=${MIRROR:?set MIRROR to the folder of bare clones <owner>+<name>/repo (see the top)}
SNAP=${1:-$MIRROR/MPEGGroup+HapticReferenceSoftware/repo}
OUT=$(mkdir -p "${2:-$ROOT/build/mpeg-reference}" && cd "${2:-$ROOT/build/mpeg-reference}" && pwd)
BIN=$OUT/build/source/Encoder/Encoder
REV=$(git --git-dir="$SNAP" rev-parse HEAD)

if [[ -x $BIN && "$(cat "$OUT/.built" 2>/dev/null)" == "$REV" ]]; then echo "$BIN"; exit 0; fi

# 1. Debian build tools, installed only when missing.
missing=()
for p in cmake g++ make ninja-build git; do dpkg -s "$p" >/dev/null 2>&1 || missing+=("$p"); done
if ((${#missing[@]})); then
  apt-get update -qq >&2 && DEBIAN_FRONTEND=noninteractive apt-get install -y -qq "${missing[@]}" >&2
fi

# 2. Export the snapshot (no work tree in a bare dir).
rm -rf "$OUT/src" && mkdir -p "$OUT/src"
git --git-dir="$SNAP" archive HEAD | tar -x -C "$OUT/src"

# 3. Third-party sources. The upstream CMake fetches them with FetchContent from GitHub /
#    git.mpeg.expert (no network here). Instead we export them from local mirrors into the
#    exact folders the CMake hard-codes (${CMAKE_BINARY_DIR}/_deps/<name>-src, also used for
#    include paths and for JSON_SCHEMA_PATH) and pass FETCHCONTENT_SOURCE_DIR_<NAME>, so no
#    CMake file is patched. Debian's rapidjson-dev (1.1.0) is too old (lacks the
#    SchemaDocument(doc, uri, len, provider) ctor) and libpugixml-dev has no pugixml::static,
#    so both come from mirrors too.  name | mirror | revision (pinned as upstream pins them)
DEPS=$OUT/build/_deps
deps=(
  "dr_libs|mackron+dr_libs|49de65c5204cb055afc1a14b11753e17d52a1d1b"
  "dj_fft|jdupuy+dj_fft|bce610fa485252a0a34493c4da611f095fdf6c1f"
  "iir|berndporr+iir1|1.9.0"
  "pugixml|zeux+pugixml|v1.12"
  # upstream tracks "master"; this is master as of the snapshot date (2024-05)
  "rapidjson|Tencent+rapidjson|ab1842a2dae061284c0a62dca1cc6d5e7e37e346"
  # upstream pins git.mpeg.expert commit 0d63838 (not public); use the public schema repo
  "hjif_specs|MPEGGroup+HapticJSONSchemas|HEAD"
)
cmake_args=()
for d in "${deps[@]}"; do
  IFS='|' read -r name repo rev <<<"$d"
  git --git-dir="$MIRROR/$repo/repo" rev-parse --verify -q "$rev^{commit}" >/dev/null ||
    { echo "missing mirror $MIRROR/$repo/repo (rev $rev)" >&2; exit 1; }
  rm -rf "$DEPS/$name-src" && mkdir -p "$DEPS/$name-src"
  git --git-dir="$MIRROR/$repo/repo" archive "$rev" | tar -x -C "$DEPS/$name-src"
  cmake_args+=("-DFETCHCONTENT_SOURCE_DIR_${name^^}=$DEPS/$name-src")
done

# 4. Patch (the only one): the public effect schema refers to itself through the remote
#    file name ("composition" items). The reference's MyRemoteSchemaDocumentProvider
#    (IOJson.cpp:58) builds a fresh SchemaDocument per remote $ref without caching, so
#    this recursed forever -> stack overflow (SIGSEGV) on every .hjif. A local "#" ref
#    means the same schema and ends the loop.
sed -i 's|"\$ref": "MPEG_haptics.effect.schema.json"|"$ref": "#"|' \
  "$DEPS/hjif_specs-src/Specifications/MPEG_haptics.effect.schema.json"

# 5. Configure + build (Release, no unit tests: Catch2 would need another download).
cmake -S "$OUT/src" -B "$OUT/build" -G Ninja -DCMAKE_BUILD_TYPE=Release \
  -DBUILD_CATCH2=OFF -DENABLE_CLANG_TIDY=OFF -DFETCHCONTENT_FULLY_DISCONNECTED=ON \
  "${cmake_args[@]}" >&2
cmake --build "$OUT/build" --target Encoder Decoder Synthesizer >&2

echo "$REV" >"$OUT/.built"
echo "$BIN"
