# Debian chroots for licvdb's tests (sourced by scripts/test-modern and scripts/test-portable):
# made with debootstrap --variant=minbase from the archive the host's apt uses, cached in $cache,
# entered with a clean environment, unmounted at exit. The caller defines say() and fail() and sets
# $cache (the cache directory) before sourcing this; then calls chroot_lock once.
# What the Blender chroots need: Blender and the add-on's test tools in both; sid's blender 5.2.2
# does not depend on python3-cattr and python3-requests, without which its extension system does
# not load.
BLENDER_PKGS=(blender python3-pytest python3-numpy python3-openvdb xvfb xauth libgl1-mesa-dri
  e2fsprogs) # chattr: test_engine.py makes a folder read-only for root
TRIXIE_PKGS=("${BLENDER_PKGS[@]}")
SID_PKGS=("${BLENDER_PKGS[@]}" python3-cattr python3-requests)

# --- the archive -----------------------------------------------------------------------------
# The Debian archive the host's apt uses (deb822 .sources or one-line .list), so that the chroots
# come from the same place (a mirror, a proxy) without configuration.
archive_url() {
  if [ -n "${LICVDB_MODERN_MIRROR:-}" ]; then echo "$LICVDB_MODERN_MIRROR"; return; fi
  local f url
  for f in /etc/apt/sources.list.d/*.sources; do
    [ -f "$f" ] || continue
    url=$(awk 'tolower($1)=="uris:" {for (i=2;i<=NF;i++) print $i}' "$f" | grep -v -- '-security' | grep '/debian/\?$' | head -1)
    [ -n "$url" ] && { echo "${url%/}"; return; }
  done
  for f in /etc/apt/sources.list /etc/apt/sources.list.d/*.list; do
    [ -f "$f" ] || continue
    url=$(awk '$1=="deb" {for (i=2;i<=NF;i++) if ($i ~ /^[a-z+]+:\/\//) {print $i; break}}' "$f" \
          | grep -v -- '-security' | grep '/debian/\?$' | head -1)
    [ -n "$url" ] && { echo "${url%/}"; return; }
  done
  fail "no Debian archive URL in /etc/apt/sources.list*; set LICVDB_MODERN_MIRROR"
}

mounted=()
cleanup() {
  local code=$? m
  for ((i = ${#mounted[@]} - 1; i >= 0; i--)); do
    m="${mounted[$i]}"
    mountpoint -q "$m" || continue # listed twice (bound again by a later stage) and already gone
    umount -R "$m" 2>/dev/null || umount -R -l "$m" 2>/dev/null || echo "${who:-chroot}: could not unmount $m" >&2
  done
  [ $code -eq 0 ] || echo "${who:-chroot}: FAILED (exit $code)" >&2
  exit $code
}
trap cleanup EXIT

# mount_chroot DIR: /proc, /sys, /dev (with /dev/pts, /dev/shm) and the host's resolv.conf.
mount_chroot() {
  local r="$1"
  mountpoint -q "$r/proc" || { mount -t proc proc "$r/proc"; mounted+=("$r/proc"); }
  mountpoint -q "$r/sys" || { mount --rbind /sys "$r/sys"; mount --make-rslave "$r/sys"; mounted+=("$r/sys"); }
  mountpoint -q "$r/dev" || { mount --rbind /dev "$r/dev"; mount --make-rslave "$r/dev"; mounted+=("$r/dev"); }
  cp -L /etc/resolv.conf "$r/etc/resolv.conf" 2>/dev/null || true
}

# bind DIR_HOST DIR_IN_CHROOT [ro]
bind() {
  mkdir -p "$2"
  # A mount left by an interrupted run (runs take turns: the lock) may show another checkout or
  # build: always bind this run's.
  if mountpoint -q "$2"; then umount -R "$2" 2>/dev/null || umount -R -l "$2"; fi
  mount --bind "$1" "$2"
  mounted+=("$2")
  if [ "${3:-}" = ro ]; then mount -o remount,bind,ro "$2"; fi
}

# in_chroot DIR CMD...: a clean environment inside the chroot.
in_chroot() {
  local r="$1"
  shift
  chroot "$r" /usr/bin/env -i HOME=/root PATH=/usr/local/sbin:/usr/local/bin:/usr/sbin:/usr/bin:/sbin:/bin \
    LANG=C.UTF-8 TERM=dumb DEBIAN_FRONTEND=noninteractive "$@"
}

# make_chroot SUITE PACKAGES...: $cache/SUITE, made from nothing or finished from where an earlier
# run stopped. Stamps: .licvdb-debootstrap (debootstrap finished), .licvdb-packages (the package
# list apt installed; written last).
make_chroot() {
  local suite="$1" r="$cache/$1" t0 url
  shift
  local want
  want="$(printf '%s\n' "$@" | sort -u | tr '\n' ' ')"
  if [ -f "$r/.licvdb-packages" ] && [ -z "$(comm -23 <(printf '%s\n' "$@" | sort -u) <(tr ' ' '\n' <"$r/.licvdb-packages" | sort -u))" ]; then
    say "$suite: reusing $r"
    mount_chroot "$r"
    return 0
  fi
  url="$(archive_url)"
  if [ ! -f "$r/.licvdb-debootstrap" ]; then
    # Unmount anything an interrupted run left behind before removing the half-made chroot.
    umount -R -l "$r/proc" "$r/sys" "$r/dev" "$r/src" "$r/build" 2>/dev/null || true
    if mount | grep -q " $r/"; then fail "$r has mounts left from another run; unmount them first"; fi
    rm -rf "$r"
    mkdir -p "$r"
    t0=$SECONDS
    say "$suite: debootstrap --variant=minbase $suite $r $url"
    debootstrap --variant=minbase "$suite" "$r" "$url" >"$cache/$suite-debootstrap.log" 2>&1 \
      || { tail -20 "$cache/$suite-debootstrap.log"; fail "debootstrap $suite (log: $cache/$suite-debootstrap.log)"; }
    # The archive's Release files are past their Valid-Until on some clocks (a snapshot mirror).
    echo 'Acquire::Check-Valid-Until "false";' >"$r/etc/apt/apt.conf.d/99licvdb-valid-until"
    echo 'Acquire::Retries "3";' >"$r/etc/apt/apt.conf.d/99licvdb-retries"
    printf 'APT::Install-Recommends "false";\nAPT::Install-Suggests "false";\n' >"$r/etc/apt/apt.conf.d/99licvdb-no-recommends"
    # Documentation is not needed to run tests: dpkg skips it (smaller, faster).
    printf 'path-exclude /usr/share/doc/*\npath-exclude /usr/share/man/*\npath-exclude /usr/share/locale/*\npath-include /usr/share/locale/locale.alias\n' \
      >"$r/etc/dpkg/dpkg.cfg.d/99licvdb-nodoc"
    echo "deb $url $suite main" >"$r/etc/apt/sources.list"
    touch "$r/.licvdb-debootstrap"
    say "$suite: debootstrap took $((SECONDS - t0)) s"
  fi
  mount_chroot "$r"
  t0=$SECONDS
  [ -f "$r/.licvdb-packages" ] && mv "$r/.licvdb-packages" "$r/.licvdb-packages.old"
  say "$suite: apt-get install $*"
  {
    in_chroot "$r" dpkg --configure -a &&
    in_chroot "$r" apt-get update -qq &&
    in_chroot "$r" apt-get install -y -qq -o Dpkg::Use-Pty=0 "$@" &&
    in_chroot "$r" apt-get clean
  } >"$cache/$suite-apt.log" 2>&1 || { tail -30 "$cache/$suite-apt.log"; fail "apt-get install in $suite (log: $cache/$suite-apt.log)"; }
  # What is installed now: this run's packages and any an earlier run installed.
  [ -f "$r/.licvdb-packages.old" ] && want="$want $(cat "$r/.licvdb-packages.old")"
  printf '%s\n' $want | sort -u | tr '\n' ' ' >"$r/.licvdb-packages"
  rm -f "$r/.licvdb-packages.old"
  say "$suite: packages took $((SECONDS - t0)) s ($(du -shx "$r" 2>/dev/null | cut -f1))"
}

versions() {
  local r="$cache/$1"
  shift
  in_chroot "$r" dpkg-query -W -f='${Package} ${Version}\n' "$@" 2>/dev/null | sed "s/^/${who:-chroot}: $(basename "$r"): /" || true
}

# chroot_lock: runs that share $cache take turns (each script holds the lock until it exits).
chroot_lock() {
  mkdir -p "$cache"
  exec 9>"$cache/.lock"
  if ! flock -n 9; then
    say "another run uses $cache; waiting for it"
    flock 9
  fi
}
