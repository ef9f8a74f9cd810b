# Run by `cmake --install` (deploy/CMakeLists.txt): the configuration, unit and sysusers
# files with the install prefix's paths written in. /usr puts configuration in /etc and data
# in /var, like GNUInstallDirs; any other prefix keeps everything below it.
set(prefix "${CMAKE_INSTALL_PREFIX}")
if(prefix STREQUAL "/usr")
  set(LINECAL_CONFIG_DIR "/etc/linecal")
  set(LINECAL_DATA_DIR "/var/lib/linecal")
else()
  set(LINECAL_CONFIG_DIR "${prefix}/etc/linecal")
  set(LINECAL_DATA_DIR "${prefix}/var/lib/linecal")
endif()
set(LINECAL_BIN_DIR "${prefix}/${LINECAL_INSTALL_BINDIR}")
set(LINECAL_SHARE_DIR "${prefix}/${LINECAL_INSTALL_DATADIR}/linecal")
set(LINECAL_DOC_DIR "${prefix}/${LINECAL_INSTALL_DOCDIR}")

set(staging "${LINECAL_DEPLOY_STAGING}")
configure_file("${LINECAL_DEPLOY_SOURCE}/linecald.json.in" "${staging}/linecald.json" @ONLY)
configure_file("${LINECAL_DEPLOY_SOURCE}/linecald.service.in" "${staging}/linecald.service" @ONLY)
configure_file("${LINECAL_DEPLOY_SOURCE}/linecal.sysusers.conf" "${staging}/linecal.conf" @ONLY)
# file(INSTALL) honours DESTDIR (packaging) like install() does.
file(INSTALL "${staging}/linecald.json" DESTINATION "${LINECAL_CONFIG_DIR}")
file(INSTALL "${staging}/linecald.service" DESTINATION "${prefix}/lib/systemd/system")
file(INSTALL "${staging}/linecal.conf" DESTINATION "${prefix}/lib/sysusers.d")
file(MAKE_DIRECTORY "$ENV{DESTDIR}${LINECAL_DATA_DIR}")
