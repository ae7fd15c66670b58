# Install rules and the Debian package (CPack DEB); README.md "Install", docs/protocol.md
# "Running as a service".
#
# Layout under the prefix (/usr for the package):
#   bin/insitu, bin/insitud                 apps/CMakeLists.txt; the project's libraries are
#                                           static, so nothing else of ours is linked at run time
#   /etc/insitu/insitud.yaml                packaging/insitud.yaml, a conffile (<prefix>/etc for
#                                           prefixes other than / and /usr)
#   lib/systemd/system/insitud.service      config/insitud.service
#   lib/udev/rules.d/99-insitu-lmc.rules    the LMC board for the insitu group
#   share/insitu/{config,calib,data}        the example jobs, worlds and patterns, calibrations
#                                           and data, as in the repository: the jobs name
#                                           ../worlds, ../patterns and ../../calib
#   share/doc/insitu/{README.md,docs/}      the documentation, its links intact
include(GNUInstallDirs)

# GNUInstallDirs puts the configuration of prefixes / and /usr in /etc, but decides when
# configuring, and `cmake --install --prefix` or cpack change the prefix afterwards: the folder
# is chosen at install time instead (file(INSTALL) prepends DESTDIR to it). jobs_dir names the
# installed jobs under the final prefix.
set(insitu_install_etc [[
  if(CMAKE_INSTALL_PREFIX MATCHES "^/(usr/?)?$")
    set(insitu_etc "/etc/insitu")
  else()
    set(insitu_etc "${CMAKE_INSTALL_PREFIX}/@CMAKE_INSTALL_SYSCONFDIR@/insitu")
  endif()
  file(READ "@CMAKE_CURRENT_SOURCE_DIR@/packaging/insitud.yaml" insitu_conf)
  string(REPLACE "\njobs_dir: /usr/share/insitu\n"
         "\njobs_dir: ${CMAKE_INSTALL_PREFIX}/@CMAKE_INSTALL_DATADIR@/insitu\n"
         insitu_conf "${insitu_conf}")
  file(WRITE "@CMAKE_CURRENT_BINARY_DIR@/insitud.yaml.install" "${insitu_conf}")
  file(INSTALL DESTINATION "${insitu_etc}" TYPE FILE RENAME insitud.yaml
       PERMISSIONS OWNER_READ OWNER_WRITE GROUP_READ WORLD_READ
       FILES "@CMAKE_CURRENT_BINARY_DIR@/insitud.yaml.install")
]])
string(CONFIGURE "${insitu_install_etc}" insitu_install_etc @ONLY)
install(CODE "${insitu_install_etc}")

# Not CMAKE_INSTALL_LIBDIR: on Debian that is lib/<multiarch>, where systemd and udev do not
# look.
install(FILES config/insitud.service DESTINATION lib/systemd/system)
install(FILES config/99-insitu-lmc.rules DESTINATION lib/udev/rules.d)

set(insitu_data ${CMAKE_INSTALL_DATADIR}/insitu)
install(DIRECTORY config/jobs config/worlds config/patterns DESTINATION ${insitu_data}/config)
install(DIRECTORY calib data DESTINATION ${insitu_data})

install(FILES README.md LICENSE DESTINATION ${CMAKE_INSTALL_DOCDIR})
# The Debian copyright file (machine-readable), where dpkg and lintian look for it.
install(FILES packaging/copyright DESTINATION ${CMAKE_INSTALL_DOCDIR})
install(DIRECTORY docs/ DESTINATION ${CMAKE_INSTALL_DOCDIR}/docs
        PATTERN "__pycache__" EXCLUDE
        PATTERN "insitu_client.py" PERMISSIONS OWNER_READ OWNER_WRITE OWNER_EXECUTE
                                               GROUP_READ GROUP_EXECUTE WORLD_READ WORLD_EXECUTE)

set(CPACK_PACKAGE_NAME insitu)
set(CPACK_PACKAGE_VERSION ${PROJECT_VERSION})
set(CPACK_PACKAGE_VENDOR "insitu")
set(CPACK_PACKAGE_CONTACT "insitu maintainers <maintainers@users.noreply.h-seed-bc13619c.example>"
    CACHE STRING "The package's Maintainer field (name <email>)")
set(CPACK_PACKAGE_DESCRIPTION_SUMMARY
    "in-situ laser machining: measure a part, then mark it in place")
# One list element a line of the control file's description (CPack indents them).
set(CPACK_PACKAGE_DESCRIPTION
    "insitu turns a 3D galvanometer scan head and a side-mounted GigE camera into a"
    "measure-then-mark laser cell: it scans the part with the head's pointer line,"
    "builds its 3D surface, places a pattern on it and marks it in focus, then checks"
    "the marks. The package holds the insitu command, the insitud daemon with its"
    "systemd unit, the udev rule for LMC galvo boards, example jobs on a simulated"
    "cell, and the documentation.")
string(JOIN "\n" CPACK_PACKAGE_DESCRIPTION ${CPACK_PACKAGE_DESCRIPTION})
set(CPACK_GENERATOR DEB)
# The package installs into /usr and /etc, so the install runs with DESTDIR (the /etc rule above
# sees the real prefix).
set(CPACK_PACKAGING_INSTALL_PREFIX /usr)
set(CPACK_SET_DESTDIR ON)
set(CPACK_STRIP_FILES ON)
set(CPACK_DEBIAN_FILE_NAME DEB-DEFAULT)
set(CPACK_DEBIAN_PACKAGE_SECTION science)
set(CPACK_DEBIAN_PACKAGE_PRIORITY optional)
# The shared libraries' packages come from dpkg-shlibdeps (dpkg-dev); adduser for postinst.
set(CPACK_DEBIAN_PACKAGE_SHLIBDEPS ON)
# The Hershey fonts' data is read at run time (text in hershey:NAME fonts, DXF SHX styles), the
# DejaVu fonts are the outline fonts text falls back to.
set(CPACK_DEBIAN_PACKAGE_DEPENDS "adduser, hershey-fonts-data, fontconfig")
set(CPACK_DEBIAN_PACKAGE_RECOMMENDS "systemd, udev, fonts-dejavu-core")
# arv-tool-0.8 lists the GigE cameras insitu can open (docs/hardware.md).
set(CPACK_DEBIAN_PACKAGE_SUGGESTS "aravis-tools")
set(CPACK_DEBIAN_PACKAGE_CONTROL_EXTRA
    ${CMAKE_CURRENT_SOURCE_DIR}/packaging/conffiles
    ${CMAKE_CURRENT_SOURCE_DIR}/packaging/postinst
    ${CMAKE_CURRENT_SOURCE_DIR}/packaging/prerm
    ${CMAKE_CURRENT_SOURCE_DIR}/packaging/postrm)
set(CPACK_DEBIAN_PACKAGE_CONTROL_STRICT_PERMISSION ON)
include(CPack)
