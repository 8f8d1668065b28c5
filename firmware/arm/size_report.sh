#!/usr/bin/env bash
# Size report for `make arm`: usage size_report.sh SIZE_TOOL LIMIT ELF OBJ...
# Flash use = .text + .data (initialised data is stored in flash too).
# Two figures: the relocatable core objects (everything in core/, used or
# not: the upper bound the 32 KiB limit applies to) and the linked probe
# image (core + newlib-nano/nosys start-up, after --gc-sections: what the
# core actually costs in a real link).
set -euo pipefail
size_tool=$1; limit=$2; elf=$3; shift 3
echo "== arm-none-eabi-size: core objects (Cortex-M4F, -Os, relocatable) =="
"$size_tool" -t "$@"
core_flash=$("$size_tool" -t "$@" | awk '/\(TOTALS\)/ {print $1 + $2}')
echo
echo "== arm-none-eabi-size: linked probe (newlib nano + nosys specs, --gc-sections) =="
"$size_tool" "$elf"
link_flash=$("$size_tool" "$elf" | awk 'NR == 2 {print $1 + $2}')
link_bss=$("$size_tool" "$elf" | awk 'NR == 2 {print $3}')
echo
echo "core objects flash (text+data): $core_flash bytes; linked image flash: $link_flash bytes, RAM (data+bss): $(( $("$size_tool" "$elf" | awk 'NR == 2 {print $2}') + link_bss )) bytes; limit $limit bytes"
if [ "$core_flash" -gt "$limit" ] || [ "$link_flash" -gt "$limit" ]; then
    echo "FAIL: firmware core exceeds the $limit byte flash budget" >&2
    exit 1
fi
echo "OK: within the $limit byte flash budget"
