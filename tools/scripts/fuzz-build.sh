#!/usr/bin/env bash
# Builds the importer fuzz targets of bvh-build/fuzz (release, AddressSanitizer, libFuzzer) and
# gathers them, stripped and gzipped (11 MiB each becomes 3.3 MiB), with their seed corpora into
# .fuzzbin/ (ignored by git), for a host without a Rust toolchain: tools/scripts/h100-fuzz.sh
# runs them there. Prints the sizes.
#
# Needs cargo-fuzz (cargo install cargo-fuzz --locked); stable Rust takes its nightly flags with
# RUSTC_BOOTSTRAP=1. Run from anywhere; FUZZBIN overrides the destination.
set -euo pipefail
cd "$(dirname "$0")/../.."
ROOT=$PWD
DEST=${FUZZBIN:-$ROOT/.fuzzbin}
TARGETS=(obj gltf description)
(cd bvh-build/fuzz && RUSTC_BOOTSTRAP=1 cargo +stable fuzz build --release 2>&1 | tail -3) ||
  { echo "cargo fuzz build failed" >&2; exit 1; }
TRIPLE=$(rustc +stable -vV | sed -n 's/^host: //p')
rm -rf "$DEST"
mkdir -p "$DEST/seeds"
for t in "${TARGETS[@]}"; do
  strip -o "$DEST/$t" "bvh-build/fuzz/target/$TRIPLE/release/$t"
  gzip -9 "$DEST/$t"
  cp -r "bvh-build/fuzz/seeds/$t" "$DEST/seeds/$t"
done
# Which shared libraries the host must provide (libFuzzer's C++ runtime among them).
ldd "bvh-build/fuzz/target/$TRIPLE/release/${TARGETS[0]}" | awk '{print $1}' | sort > "$DEST/needed-libraries.txt"
git rev-parse --short HEAD > "$DEST/commit.txt" 2>/dev/null || true
du -b "$DEST"/* | sort -k2
echo "total: $(du -sh "$DEST" | cut -f1) in $DEST"
