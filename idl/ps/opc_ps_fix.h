/*
 * opc_ps_fix.h -- force-included (gcc -include) into every C file of opc_ps.dll
 * by xtask/src/proxy.rs.
 *
 * 1. mingw-w64's rpcproxy.h lacks the prototypes of the IUnknown proxy methods
 *    that widl's proxy vtables reference; the functions themselves are exported
 *    by rpcrt4.dll (import library librpcrt4.a).
 * 2. The class ID of the DLL's PSFactoryBuffer. Without it the DLL would use
 *    the IID of the first interface in opccomn_p.c as its CLSID and, when
 *    registered, take over (and on unregistration delete) that CLSID key of an
 *    installed OPC Foundation opccomn_ps.dll. HKCR\Interface\{IID}\
 *    ProxyStubClsid32 of every interface points at this CLSID.
 */
#ifndef OPC_PS_FIX_H
#define OPC_PS_FIX_H

#include <objbase.h>

HRESULT STDMETHODCALLTYPE IUnknown_QueryInterface_Proxy(IUnknown *This, REFIID riid, void **ppvObject);
ULONG STDMETHODCALLTYPE IUnknown_AddRef_Proxy(IUnknown *This);
ULONG STDMETHODCALLTYPE IUnknown_Release_Proxy(IUnknown *This);

/* {17B524F3-2731-41AA-AFBB-78B530591805}: CLSID_PSFactoryBuffer of opc_ps.dll */
#define PROXY_CLSID_IS { 0x17b524f3, 0x2731, 0x41aa, { 0xaf, 0xbb, 0x78, 0xb5, 0x30, 0x59, 0x18, 0x05 } }

#endif /* OPC_PS_FIX_H */
