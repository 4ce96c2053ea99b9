#!/usr/bin/env bash
# Print one sha256 of everything the colcon build in scripts/setup.sh reads, for its stamp file.
# Contents: the interface package (msg_defs/), setup.py/setup.cfg/package.xml, resource/, the zoo
# index and setup.sh itself (it holds the build command). Names only: the data files setup.py
# installs (params/, launch/, checkpoints/), since --symlink-install links each of them (an edit
# shows through, a file added or removed needs a build). zeus_ros/ and sim_bridge/ are linked
# as whole folders: their sources never need a build. Usage: build_inputs.sh [ROOT] (default: ..)
set -euo pipefail
cd "${1:-$(dirname "$0")/..}"
export LC_ALL=C
{
  for file in setup.py setup.cfg package.xml scripts/setup.sh checkpoints/zoo.yaml; do
    [ -f "$file" ] && sha256sum "$file"
  done
  find msg_defs resource -type f ! -name '*.pyc' -print0 2>/dev/null | sort -z | \
    xargs -0 -r sha256sum
  find params launch checkpoints -type f ! -name '*.pyc' 2>/dev/null | sort
} | sha256sum | cut -d' ' -f1
