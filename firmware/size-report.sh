#!/usr/bin/env bash
# Flash and static RAM of the firmware images, from llvm-size (rustup component llvm-tools).
#
#   cargo build -p firmware --release --target thumbv7em-none-eabihf
#   bash firmware/size-report.sh
#
# Reports the board image (built beforehand, as above) and the QEMU image (built here, into the
# directory tests/tests/qemu_boot.rs uses, so either reuses the other's build). Exits 1 if
# either reaches the budget: 64 KiB of flash, 16 KiB of static RAM. Flash is what the loader
# writes (.vector_table + .text + .rodata + .data's initial values); static RAM is
# .data + .bss + .uninit (the stack comes on top).
set -euo pipefail
cd "$(dirname "$0")/.."

readonly FLASH_BUDGET=$((64 * 1024))
readonly RAM_BUDGET=$((16 * 1024))
readonly TARGET=thumbv7em-none-eabihf

target_dir=${CARGO_TARGET_DIR:-target}
host=$(rustc -vV | sed -n 's/^host: //p')
llvm_size="$(rustc --print sysroot)/lib/rustlib/$host/bin/llvm-size"
if [[ ! -x $llvm_size ]]; then
  echo "error: $llvm_size not found: rustup component add llvm-tools" >&2
  exit 1
fi

# Prints one image's figures; returns 1 if it is over budget.
report() {
  local name=$1 elf=$2
  if [[ ! -f $elf ]]; then
    echo "error: $elf not found: build the $name image first" >&2
    return 1
  fi
  local flash ram
  read -r flash ram < <("$llvm_size" -A "$elf" | awk '
    $1 == ".vector_table" || $1 == ".text" || $1 == ".rodata" { flash += $2 }
    $1 == ".data" { flash += $2; ram += $2 }
    $1 == ".bss" || $1 == ".uninit" { ram += $2 }
    END { print flash + 0, ram + 0 }')
  awk -v n="$name" -v f="$flash" -v r="$ram" -v fb=$FLASH_BUDGET -v rb=$RAM_BUDGET -v e="$elf" \
    'BEGIN { printf "%-5s flash %6d B (%4.1f of %d KiB)   static RAM %6d B (%4.1f of %d KiB)   %s\n",
             n, f, f / 1024, fb / 1024, r, r / 1024, rb / 1024, e }' 
  if ((flash >= FLASH_BUDGET || ram >= RAM_BUDGET)); then
    echo "error: the $name image is over budget" >&2
    return 1
  fi
}

qemu_dir="$target_dir/tmp/qemu-image"
CARGO_TARGET_DIR=$qemu_dir cargo build -q -p firmware --release --target $TARGET --features qemu

status=0
report board "$target_dir/$TARGET/release/firmware" || status=1
report qemu "$qemu_dir/$TARGET/release/firmware" || status=1
exit $status
