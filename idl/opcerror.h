/*
 * opcerror.h -- OPC Data Access error and success codes (ServerCTOPC)
 *
 * Written for this project from the OPC Data Access Custom Interface
 * Standard 2.05a and 3.00 ("Error Codes" appendix); symbol names and values
 * are those of the OPC Foundation's opcerror.h (message file opcerror.mc,
 * 1997-2003), so code written against that header compiles unchanged.
 *
 * All codes use FACILITY_ITF (0x004). Severity error: 0xC004xxxx, success:
 * 0x0004xxxx. DA 3.0 codes occupy 0x0400..0x04FF; older codes keep their
 * historical values.
 *
 * Machine-readable list (name, value, message), parsed by tests:
 * HRESULT OPC_E_INVALIDHANDLE            0xC0040001 The value of the handle is invalid.
 * HRESULT OPC_E_BADTYPE                  0xC0040004 The server cannot convert the data between the specified format and/or requested data type and the canonical data type.
 * HRESULT OPC_E_PUBLIC                   0xC0040005 The requested operation cannot be done on a public group.
 * HRESULT OPC_E_BADRIGHTS                0xC0040006 The item's access rights do not allow the operation.
 * HRESULT OPC_E_UNKNOWNITEMID            0xC0040007 The item ID is not defined in the server address space or no longer exists in the server address space.
 * HRESULT OPC_E_INVALIDITEMID            0xC0040008 The item ID does not conform to the server's syntax.
 * HRESULT OPC_E_INVALIDFILTER            0xC0040009 The filter string was not valid.
 * HRESULT OPC_E_UNKNOWNPATH              0xC004000A The item's access path is not known to the server.
 * HRESULT OPC_E_RANGE                    0xC004000B The value was out of range.
 * HRESULT OPC_E_DUPLICATENAME            0xC004000C Duplicate name not allowed.
 * HRESULT OPC_S_UNSUPPORTEDRATE          0x0004000D The server does not support the requested data rate but will use the closest available rate.
 * HRESULT OPC_S_CLAMP                    0x0004000E A value passed to write was accepted but the output was clamped.
 * HRESULT OPC_S_INUSE                    0x0004000F The operation cannot be performed because the object is being referenced.
 * HRESULT OPC_E_INVALIDCONFIGFILE        0xC0040010 The server's configuration file is an invalid format.
 * HRESULT OPC_E_NOTFOUND                 0xC0040011 The requested object (e.g. a public group) was not found.
 * HRESULT OPC_E_INVALID_PID              0xC0040203 The specified property ID is not valid for the item.
 * HRESULT OPC_E_DEADBANDNOTSET           0xC0040400 The item deadband has not been set for this item.
 * HRESULT OPC_E_DEADBANDNOTSUPPORTED     0xC0040401 The item does not support deadband.
 * HRESULT OPC_E_NOBUFFERING              0xC0040402 The server does not support buffering of data items that are collected at a faster rate than the group update rate.
 * HRESULT OPC_E_INVALIDCONTINUATIONPOINT 0xC0040403 The continuation point is not valid.
 * HRESULT OPC_S_DATAQUEUEOVERFLOW        0x00040404 Not every detected change has been returned since the server's buffer reached its limit and had to purge out the oldest data.
 * HRESULT OPC_E_RATENOTSET               0xC0040405 There is no sampling rate set for the specified item.
 * HRESULT OPC_E_NOTSUPPORTED             0xC0040406 The server does not support writing of quality and/or timestamp.
 * HRESULT OPCCPX_E_TYPE_CHANGED          0xC0040407 The dictionary and/or type description for the item has changed.
 * HRESULT OPCCPX_E_FILTER_DUPLICATE      0xC0040408 A data filter item with the specified name already exists.
 * HRESULT OPCCPX_E_FILTER_INVALID        0xC0040409 The data filter value does not conform to the server's syntax.
 * HRESULT OPCCPX_E_FILTER_ERROR          0xC004040A An error occurred when the filter value was applied to the source data.
 * HRESULT OPCCPX_S_FILTER_NO_DATA        0x0004040B The item value is empty because the data filter has excluded all fields.
 */
#ifndef __OPCERROR_H
#define __OPCERROR_H

/* DA 1.0 / 2.0 */
#define OPC_E_INVALIDHANDLE             ((HRESULT)0xC0040001L)
#define OPC_E_BADTYPE                   ((HRESULT)0xC0040004L)
#define OPC_E_PUBLIC                    ((HRESULT)0xC0040005L)
#define OPC_E_BADRIGHTS                 ((HRESULT)0xC0040006L)
#define OPC_E_UNKNOWNITEMID             ((HRESULT)0xC0040007L)
#define OPC_E_INVALIDITEMID             ((HRESULT)0xC0040008L)
#define OPC_E_INVALIDFILTER             ((HRESULT)0xC0040009L)
#define OPC_E_UNKNOWNPATH               ((HRESULT)0xC004000AL)
#define OPC_E_RANGE                     ((HRESULT)0xC004000BL)
#define OPC_E_DUPLICATENAME             ((HRESULT)0xC004000CL)
#define OPC_S_UNSUPPORTEDRATE           ((HRESULT)0x0004000DL)
#define OPC_S_CLAMP                     ((HRESULT)0x0004000EL)
#define OPC_S_INUSE                     ((HRESULT)0x0004000FL)
#define OPC_E_INVALIDCONFIGFILE         ((HRESULT)0xC0040010L)
#define OPC_E_NOTFOUND                  ((HRESULT)0xC0040011L)
#define OPC_E_INVALID_PID               ((HRESULT)0xC0040203L)

/* DA 3.0 */
#define OPC_E_DEADBANDNOTSET            ((HRESULT)0xC0040400L)
#define OPC_E_DEADBANDNOTSUPPORTED      ((HRESULT)0xC0040401L)
#define OPC_E_NOBUFFERING               ((HRESULT)0xC0040402L)
#define OPC_E_INVALIDCONTINUATIONPOINT  ((HRESULT)0xC0040403L)
#define OPC_S_DATAQUEUEOVERFLOW         ((HRESULT)0x00040404L)
#define OPC_E_RATENOTSET                ((HRESULT)0xC0040405L)
#define OPC_E_NOTSUPPORTED              ((HRESULT)0xC0040406L)

/* DA 3.0 complex data */
#define OPCCPX_E_TYPE_CHANGED           ((HRESULT)0xC0040407L)
#define OPCCPX_E_FILTER_DUPLICATE       ((HRESULT)0xC0040408L)
#define OPCCPX_E_FILTER_INVALID         ((HRESULT)0xC0040409L)
#define OPCCPX_E_FILTER_ERROR           ((HRESULT)0xC004040AL)
#define OPCCPX_S_FILTER_NO_DATA         ((HRESULT)0x0004040BL)

#endif /* __OPCERROR_H */
