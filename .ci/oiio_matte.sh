#!/bin/sh
# oiio_matte.sh EXR TYPE HEXID OUT: the Cryptomatte matte of one manifest
# entry with plain oiiotool arithmetic, as channel A (docs/cryptomatte.md,
# "Mattes and previews with oiiotool"): per rank, coverage x (id == target),
# summed over the three rank pairs.
set -eu
exr=$1 type=$2 out=$4
id=$(python3 -c 'import struct,sys; print("%.9g" % struct.unpack(">f", bytes.fromhex(sys.argv[1]))[0])' "$3")
args=""
for l in 00 01 02; do
  args="$args $exr --ch $type$l.R,$type$l.B --absdiffc $id --mulc 1e30 --mulc 1e30 --clamp:min=0:max=1 --mulc -1 --addc 1"
  args="$args $exr --ch $type$l.G,$type$l.A --mul --chsum"
done
# shellcheck disable=SC2086
oiiotool $args --add --add --chnames A -d float -o "$out"
